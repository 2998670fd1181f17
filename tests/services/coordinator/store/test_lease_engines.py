"""Tiles go only to workers that run their exploration's physics engine, and a tile of
P(success) draws only to one that runs each of its engines (both databases)."""

from __future__ import annotations

from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.exploration.tiling import TilePlan
from graspscape.services.coordinator.store.models import ObjectRow
from graspscape.services.coordinator.store.queue import lease_tiles
from graspscape.shared.specs.exploration import ExplorationSpec, PoseGridSpec
from graspscape.shared.specs.sim import SimSettings
from graspscape.shared.wire.codec import decode, encode
from graspscape.shared.wire.messages import LeaseRequest, ObjectRef
from sqlalchemy.orm import Session


def _exploration(session: Session, engine: str) -> int:
    obj = ObjectRow(kind="named", name="sphere", properties={})
    session.add(obj)
    session.commit()
    spec = ExplorationSpec(object_id=obj.id, gripper="robotiq_3f",
                           grid=PoseGridSpec(dtheta=0.6, r_max=0.02),
                           settings=SimSettings(engine=engine))
    return create_exploration(session, spec=spec, tile_target_poses=20, max_poses=10**6).id


def test_a_worker_without_mujoco_is_never_leased_a_mujoco_tile(session: Session) -> None:
    # The MuJoCo exploration is the older one: oldest-first would hand out its tiles first.
    mujoco_id = _exploration(session, "mujoco")
    pybullet_id = _exploration(session, "pybullet")
    pybullet_only: list[int] = []
    while got := lease_tiles(session, worker_id="old", n=3, lease_seconds=60,
                             engines=("pybullet",)):
        pybullet_only.extend(t.exploration_id for t in got)
    assert pybullet_only and set(pybullet_only) == {pybullet_id}
    both = lease_tiles(session, worker_id="new", n=1000, lease_seconds=60,
                       engines=("pybullet", "mujoco"))
    assert both and {t.exploration_id for t in both} == {mujoco_id}


def test_a_lease_request_without_engines_means_pybullet() -> None:
    # What a worker of before engines existed sends.
    request = LeaseRequest(worker_id="w", session_key="0" * 32, capacity=1)
    raw = encode(request).replace(b',"engines":["pybullet"]', b"")
    assert b"engines" not in raw
    request = decode(raw)
    assert isinstance(request, LeaseRequest) and request.engines == ["pybullet"]


def test_a_tile_of_draws_goes_only_to_a_worker_running_each_of_its_engines(
        session: Session) -> None:
    from datetime import UTC, datetime

    from graspscape.services.coordinator.store import tiles
    from graspscape.services.coordinator.store.models import TileRow
    from graspscape.shared.specs.results import DrawScales
    from graspscape.shared.wire.messages import TileLease, TileSample
    from sqlalchemy import update

    eid = _exploration(session, "pybullet")
    session.execute(update(TileRow).values(state="done"))  # only the draws are left
    sample = TileSample(engines=["pybullet", "mujoco"],
                        scales={"k": DrawScales(friction=0.5, mass=1.1)})
    tile = TilePlan(0, [(1.0, 0.5)], [0.01], [(0.0, 0.0, 0.0)], sample=sample)
    tiles.add_tiles(session, exploration_id=eid, level=1, round=5, tiles=[tile],
                    now=datetime.now(UTC))
    session.commit()
    assert tiles.engine_sets(("pybullet", "mujoco")) == ["mujoco", "pybullet",
                                                        "mujoco,pybullet"]
    assert not lease_tiles(session, worker_id="old", n=5, lease_seconds=60,
                           engines=("pybullet",))
    assert not lease_tiles(session, worker_id="mj", n=5, lease_seconds=60,
                           engines=("mujoco",))
    (leased,) = lease_tiles(session, worker_id="both", n=5, lease_seconds=60,
                            engines=("mujoco", "pybullet"))
    assert leased.sample == sample
    # ... and the lease message carries it to the worker as it was planned.
    message = TileLease.of(leased, object=ObjectRef(object_id=1, name="sphere"),
                           gripper="robotiq_3f", settings=SimSettings())
    assert decode(encode(message)).sample == sample
