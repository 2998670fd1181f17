"""The exports' gripper frame re-expressed in each shipped gripper's base link and in the
ACRONYM convention; docs/reference/formats.md's table says the same as the functions."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from graspscape.shared.specs.gripper import list_grippers, load_gripper
from graspscape.shared.specs.gripper_frames import (
    base_depth_m,
    palm_in_base_link,
    to_acronym,
    to_base_link,
)

DOCS = Path(__file__).resolve().parents[3] / "docs" / "reference" / "formats.md"


def table_row(name: str) -> str:
    """The row docs/reference/formats.md carries for a gripper."""
    m = np.round(to_base_link(load_gripper(name)), 4) + 0.0  # no -0
    rows = "; ".join(" ".join(f"{v:g}" for v in row) for row in m[:3])
    return f"| `{name}` | {base_depth_m(load_gripper(name)) * 1000:g} | `[{rows}]` |"


@pytest.mark.parametrize("name", list_grippers())
def test_frames_are_rigid_and_consistent(name: str) -> None:
    spec = load_gripper(name)
    palm = palm_in_base_link(spec)
    rotation = palm[:3, :3]
    assert np.allclose(rotation.T @ rotation, np.eye(3)) and np.isclose(
        np.linalg.det(rotation), 1.0)
    assert np.allclose(palm @ to_base_link(spec), np.eye(4))
    # A grasp 10 cm up the object's z, approaching down: the ACRONYM origin lies the base's
    # depth farther back along the approach, with the same axes.
    grasp = np.eye(4)
    grasp[:3, :3] = np.diag([1.0, -1.0, -1.0])
    grasp[2, 3] = 0.1
    acronym = grasp @ to_acronym(spec)
    assert np.allclose(acronym[:3, :3], grasp[:3, :3])
    assert np.isclose(acronym[2, 3], 0.1 + base_depth_m(spec))
    assert table_row(name) in DOCS.read_text(), table_row(name)


def test_franka_hand_is_acronyms_franka_frame() -> None:
    # ACRONYM's Franka gripper: hand body top 66 mm up its z, fingers along its x.
    spec = load_gripper("franka_hand")
    assert base_depth_m(spec) == pytest.approx(0.066)
    base = np.eye(4) @ to_base_link(spec)
    assert np.allclose(base[:3, 0], [0, -1, 0]) and np.allclose(base[:3, 3], [0, 0, -0.066])
