"""Grippers by name or path: GRASPSCAPE_GRIPPER_PATH before the shipped ones, paths to a TOML
spec or a URDF gripper's folder, and refusals that say what to pass instead."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from graspscape.services.local.cli import build_parser
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.gripper import (
    CONFIG_DIR,
    GRIPPER_PATH_ENV,
    find_gripper,
    list_grippers,
    load_gripper,
)

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture
def own_grippers(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    folder = tmp_path / "grippers"
    folder.mkdir()
    shutil.copy(CONFIG_DIR / "parallel_jaw.toml", folder / "my_jaw.toml")
    shutil.copytree(CONFIG_DIR / "franka_hand", folder / "my_franka")
    monkeypatch.setenv(GRIPPER_PATH_ENV, f"{tmp_path / 'nothing'}:{folder}")
    return folder


def test_names_are_searched_in_the_gripper_path_then_the_shipped(own_grippers: Path) -> None:
    assert find_gripper("my_jaw") == own_grippers / "my_jaw.toml"
    assert find_gripper("my_franka") == own_grippers / "my_franka"
    assert find_gripper("robotiq_3f") == CONFIG_DIR / "robotiq_3f.toml"
    assert {"my_jaw", "my_franka", "robotiq_3f", "franka_hand"} <= set(list_grippers())
    assert load_gripper("my_franka").kind == load_gripper("franka_hand").kind
    assert ExplorationSpec(object_id=1, gripper="my_jaw").gripper == "my_jaw"


def test_paths_work_everywhere(own_grippers: Path, monkeypatch) -> None:
    monkeypatch.delenv(GRIPPER_PATH_ENV)
    toml, folder = own_grippers / "my_jaw.toml", own_grippers / "my_franka"
    assert load_gripper(str(toml)).name == load_gripper("parallel_jaw").name
    assert ExplorationSpec(object_id=1, gripper=str(folder)).gripper == str(folder)
    monkeypatch.chdir(own_grippers)
    args = build_parser().parse_args(["explore", "mug", "--gripper", "my_jaw.toml"])
    assert args.gripper == str(toml)  # absolute: the workers run in other processes


@pytest.mark.parametrize(("given", "says"), [
    ("franka_hand/panda.urdf", "pass its folder"),
    ("no_such_hand", "add folders with GRASPSCAPE_GRIPPER_PATH"),
    ("/no/such/hand.toml", "no gripper at /no/such/hand.toml"),
])
def test_refusals_say_what_to_pass(given: str, says: str, monkeypatch, capsys) -> None:
    monkeypatch.chdir(CONFIG_DIR)
    with pytest.raises(ValueError, match=says):
        load_gripper(given)
    with pytest.raises(ValueError, match=says):
        ExplorationSpec(object_id=1, gripper=given)
    with pytest.raises(SystemExit):
        build_parser().parse_args(["explore", "mug", "--gripper", given])
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last.startswith("graspscape explore: error: argument --gripper: ") and says in last


@pytest.mark.slow  # builds the package
def test_an_installed_copy_finds_the_shipped_grippers(tmp_path: Path) -> None:
    build = tmp_path / "build"
    subprocess.run([sys.executable, "setup.py", "-q", "build_py", "--build-lib", str(build)],
                   cwd=ROOT, check=True, capture_output=True, timeout=300)
    code = ("import sys; sys.path.insert(0, sys.argv[1]);"
            "from graspscape.shared.specs import gripper as g;"
            "print(g.CONFIG_DIR); print(','.join(g.list_grippers()));"
            "print(g.load_gripper('franka_hand').kind)")
    out = subprocess.run([sys.executable, "-c", code, str(build)], capture_output=True,
                         text=True, timeout=120, cwd=tmp_path, check=True).stdout.splitlines()
    assert out[0] == str(build / "graspscape" / "configs" / "grippers")
    assert set(out[1].split(",")) == set(list_grippers())
    assert out[2] == load_gripper("franka_hand").kind
