"""Shared fixtures of the simulation tests: one evaluator per object for the whole session
(loading is the slow part; each evaluation restores a pristine state anyway)."""

from __future__ import annotations

from pathlib import Path

import pytest
from graspscape.shared.specs.gripper import load_gripper
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.evaluate import Evaluator
from graspscape.workers.sim.objects import prepare_object


@pytest.fixture(scope="session")
def sim_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("graspscape-cache")


@pytest.fixture(scope="session")
def object_cache(sim_cache: Path) -> Path:
    """The one object cache of the simulation tests: an object is prepared (V-HACD for the
    pybullet meshes, ~1 s each) once per session whichever module asks first."""
    return sim_cache / "objects"


@pytest.fixture(scope="session")
def make_evaluator(sim_cache: Path, object_cache: Path):
    made: list[Evaluator] = []

    def make(name: str, gripper: str = "robotiq_3f", settings: SimSettings | None = None,
             world_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Evaluator:
        prepared = prepare_object(ObjectSpec(name=name), object_cache)
        evaluator = Evaluator(prepared, load_gripper(gripper), settings, work_dir=sim_cache,
                              world_offset=world_offset)
        made.append(evaluator)
        return evaluator

    yield make
    for evaluator in made:
        evaluator.close()


@pytest.fixture(scope="session")
def sphere_evaluator(make_evaluator) -> Evaluator:
    return make_evaluator("sphere")


@pytest.fixture(scope="session")
def mug_evaluator(make_evaluator) -> Evaluator:
    return make_evaluator("mug")


@pytest.fixture(scope="session")
def cube_evaluator(make_evaluator) -> Evaluator:
    return make_evaluator("cube")
