"""`graspscape explore` says how an exploration ended: its last line and exit status follow
done / incomplete / failed, with the reasons of the failed tiles; running the same command
again queues the failed tiles again."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import trimesh
from graspscape.services.coordinator import db
from graspscape.services.coordinator.objects.service import create_uploaded
from graspscape.services.coordinator.store.models import ExplorationRow, ObjectRow, TileRow
from sqlalchemy import select, update

from tests.services.coordinator.dispatch.support import REPO


def _explore(mesh: Path, data_dir: Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "graspscape.services.local.cli", "explore", str(mesh),
               "--mass", "0.2", "--dtheta", "60", "--r-min", "0.02", "--r-max", "0.02",
               "--levels", "0", "--procs", "1", "--data-dir", str(data_dir), "--quiet"]
    return subprocess.run(command, capture_output=True, text=True, timeout=300, cwd=REPO,
                          env=env)


@pytest.mark.slow
def test_explore_ends_failed_with_the_reason_and_a_rerun_retries(tmp_path: Path) -> None:
    mesh = tmp_path / "box.stl"
    mesh.write_bytes(trimesh.creation.box(extents=(0.05, 0.05, 0.1)).export(file_type="stl"))
    data_dir = tmp_path / "run"
    url = f"sqlite:///{data_dir / 'coordinator.db'}"
    data_dir.mkdir()
    db.upgrade(url)
    engine = db.make_engine(url)
    sessions = db.make_sessionmaker(engine)
    with sessions() as session:
        # The object the command will store, but with its mesh lost: every worker's fetch
        # is refused (not_found), so each tile fails its three attempts.
        row, _ = create_uploaded(session, filename=mesh.name, data=mesh.read_bytes(),
                                 properties={"mass_kg": 0.2})
        object_id = row.id
        session.execute(update(ObjectRow).where(ObjectRow.id == object_id).values(mesh=None))
        session.commit()
    env = {**os.environ, "GRASPSCAPE_CACHE_DIR": str(tmp_path / "cache")}

    run = _explore(mesh, data_dir, env)
    assert run.returncode == 1, run.stdout + run.stderr  # was 1 too, but after "done"
    last = run.stdout.strip().splitlines()[-1]
    with sessions() as session:
        (exploration,) = session.scalars(select(ExplorationRow)).all()
        assert exploration.status == "failed" and exploration.poses_done == 0
        n = exploration.tiles_total
        assert set(session.scalars(select(TileRow.attempts))) == {3}
    assert re.fullmatch(
        rf"failed: 0 of {exploration.poses_total} poses stored in \d+ s; {n} tiles failed: "
        rf"explore-p0-\d+: mesh \w+: not_found: no mesh with content hash \w+ \({n} tiles\); "
        r"run the same command again to retry them", last), last
    with sessions() as session:
        session.execute(update(ObjectRow).where(ObjectRow.id == object_id)
                        .values(mesh=mesh.read_bytes()))  # the mesh is back
        session.commit()

    rerun = _explore(mesh, data_dir, env)
    assert rerun.returncode == 0, rerun.stdout + rerun.stderr
    last = rerun.stdout.strip().splitlines()[-1]
    total = exploration.poses_total
    assert re.fullmatch(rf"done: {total} of {total} poses stored in \d+ s", last), last
    with sessions() as session:
        (again,) = session.scalars(select(ExplorationRow)).all()  # the same one, resumed
        assert (again.id, again.status, again.poses_done) == (exploration.id, "done", total)
    engine.dispose()
