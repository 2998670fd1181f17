"""The one object validation, as a pure function: units, and when bodies count as apart."""

from __future__ import annotations

import pytest
import trimesh
from graspscape.shared.specs.object_checks import check_object, gripper_reach_m
from graspscape.shared.specs.objects import ObjectSpec
from pydantic import ValidationError

SPEC = ObjectSpec(mesh_path="m.stl", mass_kg=0.2)


def _cubes(gap_m: float, size_m: float = 0.05) -> trimesh.Trimesh:
    a = trimesh.creation.box(extents=(size_m,) * 3)
    b = a.copy()
    b.apply_translation((size_m + gap_m, 0.0, 0.0))
    return trimesh.util.concatenate([a, b])


def test_units_multiply_scale_and_are_for_mesh_files_only() -> None:
    assert ObjectSpec(mesh_path="m.obj", units="cm", scale=2.0).metres_per_unit == 0.02
    assert ObjectSpec(mesh_path="m.obj").metres_per_unit == 1.0
    with pytest.raises(ValidationError, match="units apply to mesh files"):
        ObjectSpec(name="cube", units="mm")


@pytest.mark.parametrize(("gap_m", "bodies"), [(0.001, 1), (0.01, 1), (0.024, 1), (0.03, 2),
                                               (0.3, 2)])
def test_bodies_are_apart_beyond_half_the_largest_piece(gap_m: float, bodies: int) -> None:
    report = check_object(_cubes(gap_m), SPEC, label="m")
    assert report.errors == [] and report.bodies == bodies
    assert any(w.code == "disconnected" for w in report.warnings) == (bodies > 1)


def test_overlapping_hulls_are_one_body_and_a_triangle_soup_is_warned() -> None:
    a, b = trimesh.creation.box(extents=(0.05, 0.05, 0.05)), trimesh.creation.icosphere(
        radius=0.03)
    b.apply_translation((0.03, 0.0, 0.0))
    hulls = trimesh.util.concatenate([a, b])  # as YCB collision hulls are: overlapping pieces
    assert check_object(hulls, SPEC, label="m", needs_volume=False).bodies == 1
    pieces = []
    for i in range(2100):
        t = trimesh.creation.box(extents=(0.001, 0.001, 0.001))
        t.apply_translation(((i % 50) * 0.002, (i // 50) * 0.002, 0.0))
        pieces.append(t)
    soup = check_object(trimesh.util.concatenate(pieces), SPEC, label="m")
    assert "2100 separate pieces" in soup.warnings[-1].message


def test_the_size_limits_follow_the_gripper_reach() -> None:
    reach = gripper_reach_m()
    assert reach == pytest.approx(0.126, abs=0.001)  # the Robotiq hand, the longest shipped
    big = trimesh.creation.box(extents=(9.9 * reach, 0.05, 0.05))
    report = check_object(big, SPEC, label="m")
    assert report.errors == [] and [w.code for w in report.warnings] == ["large"]
    assert check_object(trimesh.creation.box(extents=(10.1 * reach, 0.05, 0.05)), SPEC,
                        label="m").errors[0].code == "too_large"
    tiny = check_object(trimesh.creation.box(extents=(0.0009,) * 3), SPEC, label="m")
    assert tiny.errors[0].code == "too_small"
