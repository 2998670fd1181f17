"""The worker's side of the one object validation (issue #19, finding 6): the bad objects of
the finding, the names and sizes both sides know, and the URDF import.

Real meshes through the real preparation (`prepare_object`, what a worker runs on its first
tile of an object) and through `graspscape eval-pose`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from graspscape.services.local.cli import main
from graspscape.shared.specs.object_names import BUILTIN_NAMES, NAMED_SIZE_M, PB_NAMES
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.workers.sim.objects import (
    MassMissing,
    NotWatertight,
    ObjectError,
    WrongSize,
    inspect_object,
    list_builtin_objects,
    prepare_object,
)
from graspscape.workers.sim.objects.builtins import BUILTINS
from graspscape.workers.sim.objects.catalog import PB_ENTRIES, ycb_root

from tests import object_meshes as meshes

needs_ycb = pytest.mark.skipif(not ycb_root().is_dir(), reason="YCB folder not present")


@pytest.fixture(scope="module")
def cache_dir(object_cache: Path) -> Path:
    return object_cache


def _file(tmp_path: Path, name: str, data: bytes) -> str:
    path = tmp_path / name
    path.write_bytes(data)
    return str(path)


def test_two_bodies_far_apart_prepare_with_a_warning(tmp_path: Path, cache_dir: Path) -> None:
    spec = ObjectSpec(mesh_path=_file(tmp_path, "two.stl", meshes.stl_bytes(meshes.two_bodies())),
                      mass_kg=0.2)
    prepared = prepare_object(spec, cache_dir)
    (warning,) = prepared.warnings
    assert "2 bodies up to 0.3 m apart" in warning
    assert inspect_object(spec).bodies == 2
    # One body, or bodies touching, is no warning.
    one = ObjectSpec(mesh_path=_file(tmp_path, "one.stl", meshes.stl_bytes(meshes.box(0.05))),
                     mass_kg=0.2)
    assert prepare_object(one, cache_dir).warnings == ()


@pytest.mark.parametrize(
    ("mesh", "error", "words"),
    [
        (meshes.open_tube(), NotWatertight, r"not watertight \(64 open edges\)"),
        (meshes.box(10_000.0), WrongSize, r"too large: 1e\+04 m across.*gripper reaches 0.126"),
        (meshes.box(1e-6), WrongSize, r"too small: 1e-06 m across.*units"),
    ],
    ids=["open-tube", "10-km", "1-um"],
)
def test_bad_objects_are_refused_by_the_worker_as_at_upload(
    tmp_path: Path, cache_dir: Path, mesh: trimesh.Trimesh, error: type[ObjectError], words: str
) -> None:
    spec = ObjectSpec(mesh_path=_file(tmp_path, "bad.stl", meshes.stl_bytes(mesh)), mass_kg=0.2)
    with pytest.raises(error, match=words):
        prepare_object(spec, cache_dir)
    assert [e.code for e in inspect_object(spec).errors] != []


@pytest.mark.slow  # seconds of physics or subprocess: the default run stays near 90 s
def test_units_bring_a_millimetre_mesh_to_metres(tmp_path: Path, cache_dir: Path) -> None:
    path = _file(tmp_path, "bunny_mm.obj", meshes.bunny_in_mm())
    with pytest.raises(WrongSize, match="give the file's units"):
        prepare_object(ObjectSpec(mesh_path=path, mass_kg=0.15), cache_dir)
    with pytest.raises(WrongSize, match=r"1\.97 m across"):
        prepare_object(ObjectSpec(mesh_path=str(meshes.RAW_BUNNY), mass_kg=0.15), cache_dir)
    in_mm = prepare_object(ObjectSpec(mesh_path=path, mass_kg=0.15, units="mm"), cache_dir)
    by_scale = prepare_object(ObjectSpec(mesh_path=path, mass_kg=0.15, scale=0.001), cache_dir)
    assert max(in_mm.extents) == pytest.approx(0.0987, abs=0.002)
    assert in_mm.content_hash == by_scale.content_hash  # the same object, however it is said
    bunny = prepare_object(ObjectSpec(name="pb:bunny"), cache_dir)
    assert in_mm.extents == pytest.approx(bunny.extents, rel=1e-6)


def test_a_mesh_file_without_mass_is_refused(tmp_path: Path, cache_dir: Path) -> None:
    path = _file(tmp_path, "box.stl", meshes.stl_bytes(meshes.box(0.05)))
    with pytest.raises(MassMissing, match="give mass_kg"):
        prepare_object(ObjectSpec(mesh_path=path), cache_dir)


def test_every_named_object_passes_without_warning_and_both_sides_know_its_size() -> None:
    assert set(BUILTIN_NAMES) == set(BUILTINS) and set(PB_NAMES) == set(PB_ENTRIES)
    assert set(NAMED_SIZE_M) == {*BUILTIN_NAMES, *(f"pb:{n}" for n in PB_NAMES)}
    for name in list_builtin_objects():
        report = inspect_object(ObjectSpec(name=name))
        assert report.errors == [] and report.warnings == [], name
        if name in NAMED_SIZE_M:  # what the coordinator checks `scale` with at upload
            assert max(report.extents_m) == pytest.approx(NAMED_SIZE_M[name], rel=0.02), name


@needs_ycb
@pytest.mark.parametrize("folder", ["YcbPowerDrill", "YcbChipsCan"])
def test_a_ycb_name_and_its_urdf_path_give_the_same_object(
    cache_dir: Path, folder: str
) -> None:
    """The URDF's mass, friction and mesh scale (0.95 0.95 1 for the chips can) are kept."""
    named = prepare_object(ObjectSpec(name=f"ycb:{folder}"), cache_dir)
    by_path = prepare_object(
        ObjectSpec(mesh_path=str(ycb_root() / folder / "model.urdf")), cache_dir)
    assert by_path.name == folder
    for field in ("content_hash", "mass_kg", "friction", "inertia_diag", "extents",
                  "com_in_source", "decomposition"):
        assert getattr(by_path, field) == getattr(named, field), field
    assert len(by_path.collision_parts) == len(named.collision_parts)
    for a, b in zip(by_path.collision_parts, named.collision_parts, strict=True):
        assert np.array_equal(a, b)
    if folder == "YcbChipsCan":  # scale="0.95 0.95 1.0": narrower than tall, as the file says
        raw = inspect_object(ObjectSpec(name=f"ycb:{folder}")).extents_m
        assert raw is not None and raw[0] < 0.95 * raw[2]
    # Overrides apply the same way to both.
    heavier = {"mass_kg": 1.5, "friction": 0.4}
    a = prepare_object(ObjectSpec(name=f"ycb:{folder}", **heavier), cache_dir)
    b = prepare_object(ObjectSpec(mesh_path=str(ycb_root() / folder / "model.urdf"), **heavier),
                       cache_dir)
    assert (a.mass_kg, a.friction, a.inertia_diag) == (b.mass_kg, b.friction, b.inertia_diag)


def test_eval_pose_prints_warnings_and_refuses_bad_objects(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pose = ["--theta", "0", "--phi", "0"]
    tube = _file(tmp_path, "tube.stl", meshes.stl_bytes(meshes.open_tube()))
    assert main(["eval-pose", tube, "--mass", "0.2", *pose]) == 1
    assert "not watertight" in capsys.readouterr().err
    bunny = _file(tmp_path, "bunny_mm.obj", meshes.bunny_in_mm())
    assert main(["eval-pose", bunny, "--mass", "0.15", *pose]) == 1
    assert "too large" in capsys.readouterr().err
    two = _file(tmp_path, "two.stl", meshes.stl_bytes(meshes.two_bodies()))
    assert main(["eval-pose", two, "--mass", "0.2", "--scale", "0.5", *pose]) == 0
    out = capsys.readouterr()
    assert "warning: two: mesh is 2 bodies up to 0.15 m apart" in out.err
    assert '"outcome"' in out.out
