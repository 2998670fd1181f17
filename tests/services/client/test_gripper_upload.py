"""`graspscape submit --gripper PATH --url`: a gripper that only this machine has is uploaded
(POST /grippers) and the spec names it by the answer; a shipped one goes by name."""

from __future__ import annotations

import shutil

from graspscape.services.client import Client
from graspscape.services.coordinator.store.models import ExplorationRow, GripperRow
from graspscape.services.local.cli import main
from graspscape.shared.specs.gripper import CONFIG_DIR

GRID = ["--dtheta", "90", "--r-min", "0.01", "--r-max", "0.01", "--levels", "0"]


def test_submit_uploads_a_local_gripper_and_names_it_by_its_hash(
    live_url, sessions, tmp_path, capsys
) -> None:
    folder = tmp_path / "my_pr2"
    shutil.copytree(CONFIG_DIR / "pr2_gripper", folder)
    assert main(["submit", "sphere", *GRID, "--gripper", str(folder), "--url", live_url]) == 0
    captured = capsys.readouterr()
    eid = int(captured.out.strip())
    assert "uploaded as sha256:" in captured.err
    with sessions() as s:
        row = s.get(ExplorationRow, eid)
        assert row.spec["gripper"].startswith("sha256:")
        assert s.get(GripperRow, row.gripper_hash).kind == "urdf"
    # The client uploads a folder's gripper.toml path as the folder: the same archive.
    with Client(live_url) as api:
        again = api.add_gripper(folder / "gripper.toml")
    assert again.gripper == row.spec["gripper"]
    # ... and a later submit names it by that name alone.
    assert main(["submit", "sphere", *GRID, "--gripper", again.gripper, "--url", live_url]) == 0
    later = int(capsys.readouterr().out.strip())
    with sessions() as s:
        assert s.get(ExplorationRow, later).gripper_hash == again.content_hash


def test_submit_names_a_shipped_gripper_as_given(live_url, sessions, capsys) -> None:
    assert main(["submit", "sphere", *GRID, "--gripper", "parallel_jaw", "--url",
                 live_url]) == 0
    eid = int(capsys.readouterr().out.strip())
    with sessions() as s:
        row = s.get(ExplorationRow, eid)
        assert row.spec["gripper"] == "parallel_jaw" and row.gripper_hash is None
