"""A gripper of one's own travels to workers as meshes do: packed at submit, stored by the
hash of its archive, fetched over a real zenoh get on loopback, checked and unpacked into the
worker's cache. A worker that has no copy of the gripper evaluates a pose with it; a tampered
archive is refused."""

from __future__ import annotations

import hashlib
import io
import zipfile
from pathlib import Path

import pytest
import zenoh
from graspscape.services.coordinator.dispatch.service import Dispatcher
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.objects.service import create_named
from graspscape.services.coordinator.store.models import ExplorationRow, GripperRow
from graspscape.shared.specs.exploration import ExplorationSpec, PoseGridSpec, RefinementSpec
from graspscape.shared.specs.gripper import CONFIG_DIR, GRIPPER_PATH_ENV
from graspscape.shared.specs.results import Outcome
from graspscape.shared.wire.session import zenoh_config
from graspscape.workers.runtime.grippers import GripperCache, GripperFetchError
from graspscape.workers.runtime.objects import ObjectCache
from sqlalchemy import update
from sqlalchemy.orm import Session, sessionmaker

from tests.services.coordinator.dispatch.test_protocol import (  # noqa: F401 (fixtures)
    client,
    dispatcher,
    lease,
    registry,
)


def own_gripper(folder: Path) -> Path:
    """The shipped parallel jaw under another name, in a folder no worker searches."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "my_jaw.toml"
    text = (CONFIG_DIR / "parallel_jaw.toml").read_text()
    path.write_text(text.replace('name = "parallel_jaw"', 'name = "my_jaw"'))
    return path


def _submit(sessions: sessionmaker[Session], gripper: str) -> int:
    with sessions() as session:
        obj, _ = create_named(session, name="sphere", properties={}, shared_dir=None)
        spec = ExplorationSpec(
            object_id=obj.id, gripper=gripper,
            grid=PoseGridSpec(dtheta=1.5707963, r_min=0.01, r_max=0.02, dr=0.01),
            refinement=RefinementSpec(levels=0))
        return create_exploration(session, spec=spec, tile_target_poses=2,
                                  max_poses=100_000).id


def test_a_shipped_gripper_travels_by_name(
    client: zenoh.Session, any_sessions: sessionmaker[Session]  # noqa: F811
) -> None:
    _submit(any_sessions, "parallel_jaw")
    (tile,) = lease(client, "w-1")
    assert tile.gripper_ref is not None and tile.gripper_ref.content_hash is None
    assert tile.gripper_ref.name == "parallel_jaw"
    # By a path into the shipped folder (which may be elsewhere on a worker): by its archive.
    by_path = _submit(any_sessions, str(CONFIG_DIR / "experimental" / "robotiq_2f85"))
    with any_sessions() as session:
        stored = session.get(ExplorationRow, by_path).gripper_hash
        assert stored is not None and session.get(GripperRow, stored).kind == "urdf"


def test_a_worker_without_the_gripper_fetches_it_and_evaluates_a_pose(
    dispatcher: Dispatcher, client: zenoh.Session,  # noqa: F811
    any_sessions: sessionmaker[Session], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    from graspscape.workers.runtime.config import WorkerConfig
    from graspscape.workers.runtime.process import WorkerProcess

    source = own_gripper(tmp_path / "mine")
    exploration_id = _submit(any_sessions, str(source))
    source.unlink()  # the coordinator packed it at submit: nobody needs the file now
    monkeypatch.setenv(GRIPPER_PATH_ENV, "")
    with any_sessions() as session:
        stored = session.get(ExplorationRow, exploration_id).gripper_hash
        assert session.get(GripperRow, stored).name == "my_jaw"
    worker = WorkerProcess(WorkerConfig(connect=dispatcher.zenoh_settings.listen, procs=1,
                                        name="far", cache_dir=tmp_path / "cache",
                                        query_timeout_s=10), 0)
    worker.session = zenoh.open(
        zenoh_config(mode="client", connect=dispatcher.zenoh_settings.listen))
    try:
        # What WorkerProcess.run sets up once connected (the test drives the process).
        worker.cache_dir = tmp_path / "cache"
        worker.objects = ObjectCache(worker.session, worker.cache_dir, 10)
        worker.grippers = GripperCache(worker.session, worker.cache_dir, 10)
        (tile, *_) = worker._lease()
        assert tile.gripper_ref.content_hash == stored and tile.gripper_ref.kind == "toml"
        batch = worker._evaluate_tile(tile, tile.poses()[:1])
    finally:
        worker.session.close()
    assert batch is not None and len(batch.results) == 1, batch
    (result,) = batch.results
    assert result.error is None and result.outcome in set(Outcome)
    assert worker.grippers.fetched == 1
    unpacked = tmp_path / "cache" / "grippers" / stored / "spec.toml"
    assert 'name = "my_jaw"' in unpacked.read_text()
    # A second process of the worker shares the cache folder: nothing fetched again.
    again = GripperCache(client, tmp_path / "cache", timeout_s=10)
    assert again.gripper(tile.gripper_ref, tile.gripper) == str(unpacked)
    assert again.fetched == 0


def _zip(members: dict[str, bytes]) -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as archive:
        for name, body in members.items():
            archive.writestr(name, body)
    return out.getvalue()


def test_a_tampered_or_unsafe_archive_is_refused(
    client: zenoh.Session, any_sessions: sessionmaker[Session], tmp_path: Path  # noqa: F811
) -> None:
    exploration_id = _submit(any_sessions, str(own_gripper(tmp_path / "mine")))
    (tile,) = lease(client, "w-1")
    stored = tile.gripper_ref.content_hash
    evil = _zip({"../../escape.toml": b'name = "x"'})
    evil_hash = hashlib.sha256(evil).hexdigest()
    with any_sessions() as session:
        session.execute(update(GripperRow).where(GripperRow.content_hash == stored)
                        .values(archive=b"PK tampered"))
        session.add(GripperRow(content_hash=evil_hash, kind="toml", name="evil", archive=evil))
        session.commit()
        assert session.get(ExplorationRow, exploration_id).gripper_hash == stored
    cache = GripperCache(client, tmp_path / "cache", timeout_s=10)
    with pytest.raises(GripperFetchError, match="another hash") as refused:
        cache.gripper(tile.gripper_ref, tile.gripper)
    assert not refused.value.transient
    unsafe = tile.gripper_ref.model_copy(update={"content_hash": evil_hash})
    with pytest.raises(GripperFetchError, match="only relative paths"):
        cache.gripper(unsafe, tile.gripper)
    missing = tile.gripper_ref.model_copy(update={"content_hash": "0" * 64})
    with pytest.raises(GripperFetchError, match="not_found"):
        cache.gripper(missing, tile.gripper)
    assert not (tmp_path / "escape.toml").exists()
    assert sorted(p.name for p in (tmp_path / "cache" / "grippers").iterdir()
                  if not p.name.endswith(".lock")) == []
