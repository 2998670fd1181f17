"""`graspscape explore`: the one local command runs coordinator, zenoh and workers end to end
and leaves the results, the map picture and the manifold table where it says."""

from __future__ import annotations

import csv
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest


@pytest.mark.slow
def test_explore_maps_an_object_on_this_machine(tmp_path: Path):
    command = [sys.executable, "-m", "graspscape.services.local.cli", "explore", "sphere",
               "--dtheta", "60", "--r-min", "0.02", "--r-max", "0.02", "--levels", "0",
               "--procs", "1", "--data-dir", str(tmp_path), "--quiet"]
    run = subprocess.run(command, capture_output=True, text=True, timeout=240)
    assert run.returncode == 0, run.stderr
    results = Path(re.search(r"results: (\S+)", run.stdout).group(1))
    picture = Path(re.search(r"map: (\S+)", run.stdout).group(1))
    table = Path(re.search(r"table: (\S+)\)", run.stdout).group(1))
    with results.open() as fh:
        rows = list(csv.DictReader(fh))
    keys = [row["pose_key"] for row in rows]
    assert keys and len(keys) == len(set(keys))  # every pose once
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    manifolds = json.loads(table.read_text())
    # A sphere grasped from anywhere is one kind of grasp.
    assert [m["name"] for m in manifolds] == ["A"]
    # Its best grasp, with what backs it (levels 0: no certification rounds, no draws).
    assert "best grasp by P(success) per large manifold" in run.stdout
    assert re.search(r"^  A: .* P\(success\) not sampled; not certified: undecided at "
                     r"P ≥ 0.9$", run.stdout, re.M), run.stdout
    assert "pybullet build time" not in run.stderr

    # The same command again: the stored results, nothing explored again; --new explores.
    again = subprocess.run(command, capture_output=True, text=True, timeout=240)
    assert again.returncode == 0, again.stderr
    n = len(keys)
    assert again.stdout.strip().splitlines()[-1].startswith(f"done: {n} of {n} poses stored")
    assert f"exploration {_id(run.stdout)})" in again.stdout
    new = subprocess.run([*command, "--new"], capture_output=True, text=True, timeout=240)
    assert new.returncode == 0, new.stderr
    assert _id(new.stdout) == _id(run.stdout) + 1


def _id(stdout: str) -> int:
    return int(re.search(r"\(exploration (\d+)\)", stdout).group(1))


@pytest.mark.slow
def test_explore_with_a_gripper_of_ones_own(tmp_path: Path):
    import shutil

    from graspscape.shared.specs.gripper import CONFIG_DIR

    own = tmp_path / "hands" / "my_jaw.toml"
    own.parent.mkdir()
    shutil.copy(CONFIG_DIR / "parallel_jaw.toml", own)
    command = [sys.executable, "-m", "graspscape.services.local.cli", "explore", "sphere",
               "--gripper", "my_jaw.toml", "--dtheta", "60", "--r-min", "0.02", "--r-max",
               "0.02", "--levels", "0", "--procs", "1", "--data-dir", str(tmp_path / "d"),
               "--quiet"]
    run = subprocess.run(command, capture_output=True, text=True, timeout=240, cwd=own.parent)
    assert run.returncode == 0, run.stderr
    assert re.search(r"^done: (\d+) of \1 poses stored", run.stdout, re.M), run.stdout
    import sqlite3

    with sqlite3.connect(tmp_path / "d" / "coordinator.db") as db:
        (spec,) = db.execute("select spec from explorations").fetchone()
    assert json.loads(spec)["gripper"] == str(own)


@pytest.mark.slow
def test_explore_on_a_table_drives_one_exploration_per_resting_pose(tmp_path: Path):
    # A cube rests on any of its six faces alike: four resting poses, at most four.
    command = [sys.executable, "-m", "graspscape.services.local.cli", "explore", "cube",
               "--support", "plane", "--dtheta", "90", "--r-min", "0.08", "--r-max", "0.08",
               "--levels", "0", "--robustness", "none", "--procs", "1",
               "--data-dir", str(tmp_path), "--quiet"]
    run = subprocess.run(command, capture_output=True, text=True, timeout=400)
    assert run.returncode == 0, run.stderr
    ids = [int(i) for i in re.findall(r"\(exploration (\d+)\)", run.stdout)]
    assert len(ids) == 4 and ids == sorted(set(ids))
    assert len(re.findall(r"^done: ", run.stdout, re.M)) == 4
    rows = []
    for results in re.findall(r"results: (\S+)", run.stdout):
        with Path(results).open() as fh:
            rows += list(csv.DictReader(fh))
    # From below (θ = 180° in the object frame is under the cube only where the cube
    # rests on its -z face) some starts are in the table, stored without a simulation.
    assert any(row["outcome"] == "infeasible_table" for row in rows)
    again = subprocess.run(command, capture_output=True, text=True, timeout=400)
    assert again.returncode == 0, again.stderr
    assert [int(i) for i in re.findall(r"\(exploration (\d+)\)", again.stdout)] == ids
