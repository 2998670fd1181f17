"""`gripper check` explains: a .urdf file is answered with what to pass instead, a hand that
holds nothing gets the reasons, and held grasps with μs ≈ 0 a warning."""

from __future__ import annotations

from pathlib import Path

from graspscape.services.local.cli import main
from graspscape.shared.specs.gripper import CONFIG_DIR
from graspscape.workers.sim.gripper.check import JointTravel, Trial
from graspscape.workers.sim.gripper.check_explain import why_no_hold, zero_quality_warnings

DIGITS = {"palm": ["palm"], "L": ["L_1", "L_2"], "R": ["R_1"]}


def _trial(start: str, links: list[str], viable: bool = False, mu_s: float = 0.0,
           obj: str = "sphere") -> Trial:
    return Trial(object=obj, start=start, outcome="held" if viable else "no_grasp",
                 viable=viable, mu_s=mu_s, links_in_contact=links)


def _joint(name: str, moved: bool) -> JointTravel:
    return JointTravel(joint=name, vendor=f"v_{name}", open=0.0, closed=0.5 if moved else 0.0,
                       moved=moved)


def test_why_a_hand_holds_nothing() -> None:
    trials = [_trial("side", ["L_2"]), _trial("top", []), _trial("side rolled 90°", ["L_1",
                                                                                    "palm"]),
              _trial("side", ["R_1", "L_1"], obj="cube")]
    joints = [_joint("L_1", True), _joint("R_1", False), _joint("L_spread", False)]
    why = why_no_hold("sphere", trials, joints, DIGITS)
    assert why == [
        "finger R never touched the sphere",
        "joint R_1 (v_R_1) never moved (check the closing sign and the effort's units: N·m "
        "for a revolute joint, N for a prismatic one)",
        "from top nothing touched the sphere (the hand closes short of it: the opening, the "
        "reach or the palm origin)",
        "from side only L_2 touched it (one link cannot hold an object against gravity)",
    ]
    # A hand whose every finger touched and moved, with two links each time: no reason made up.
    fine = [_trial("side", ["L_1", "R_1"])]
    assert why_no_hold("sphere", fine, [_joint("L_1", True)], DIGITS) == []


def test_held_with_zero_quality_is_warned() -> None:
    trials = [_trial("side", ["L_1", "R_1"], viable=True, mu_s=0.0),
              _trial("top", ["L_1", "R_1"], viable=True, mu_s=0.31),
              _trial("side", [], viable=False, mu_s=0.0)]
    (warning,) = zero_quality_warnings(trials)
    assert warning.startswith("sphere, side: held with μs 0.00 — the contacts (L_1, R_1)")


def test_a_urdf_file_is_answered_with_what_to_pass(tmp_path: Path, monkeypatch,
                                                   capsys) -> None:
    monkeypatch.chdir(tmp_path)
    urdf = CONFIG_DIR / "franka_hand" / "panda.urdf"
    assert main(["gripper", "check", str(urdf)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("graspscape gripper: error: ") and "\n" not in err
    assert f"pass its folder ({urdf.parent}) which has a gripper.toml" in err
    assert list(tmp_path.iterdir()) == []  # refused before any picture was written
    lone = tmp_path / "hand.urdf"
    lone.write_text("<robot name='x'/>")
    assert main(["gripper", "check", str(lone)]) == 1
    assert f"pass its folder ({tmp_path}), with a gripper.toml" in capsys.readouterr().err
