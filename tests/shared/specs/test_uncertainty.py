"""The uncertainty model: presets, validation and repeatable, extendable draws."""

from __future__ import annotations

import math
from concurrent.futures import ProcessPoolExecutor

import pytest
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.uncertainty import UncertaintyModel, draw, draws, perturbed
from pydantic import ValidationError

KEY = Pose(theta=1.0, phi=2.0, r=0.01, roll=0.0, pitch=0.0, yaw=0.0).key()


def test_presets_and_overrides() -> None:
    field = UncertaintyModel(preset="field")
    assert (field.position_mm, field.orientation_deg, field.form) == (5.0, 5.0, "ball")
    assert field.friction_scale == (0.5, 1.0) and field.mass_scale == (0.8, 1.2)
    lab = UncertaintyModel()
    assert (lab.preset, lab.position_mm, lab.orientation_deg) == ("lab", 2.0, 2.0)
    assert UncertaintyModel(preset="field", position_mm=3.0).position_mm == 3.0
    assert UncertaintyModel(preset="none").describe().startswith("none: pose σ 0 mm")
    with pytest.raises(ValidationError, match="friction_scale"):
        UncertaintyModel(preset="custom", friction_scale=(1.0, 0.5))


def test_draws_repeat_and_extend() -> None:
    model = UncertaintyModel(preset="field")
    ten = draws(KEY, model, 10)
    assert draws(KEY, model, 10) == ten
    assert draws(KEY, model, 20)[:10] == ten  # a larger sample extends a smaller one
    assert draws(KEY, model, 5, start=5) == ten[5:]
    assert draws(KEY, model, 10, stream="fresh") != ten  # the fresh check's own stream
    assert draws(KEY, UncertaintyModel(preset="lab"), 10) != ten
    for d in ten:  # the ball's radius, the scales' ranges
        assert math.dist(d.position, (0, 0, 0)) <= 0.005 + 1e-12
        assert math.dist(d.rotation, (0, 0, 0)) <= math.radians(5) + 1e-12
        assert 0.5 <= d.friction_scale <= 1.0 and 0.8 <= d.mass_scale <= 1.2
        assert d.effort_scale == 1.0


def _chunk(args: tuple[int, int]) -> list:
    start, n = args
    return draws(KEY, UncertaintyModel(preset="field"), n, start=start)


def test_same_draws_with_any_worker_count() -> None:
    whole = draws(KEY, UncertaintyModel(preset="field"), 24)
    for workers in (1, 3):
        chunks = [(i, 24 // workers) for i in range(0, 24, 24 // workers)]
        with ProcessPoolExecutor(max_workers=workers) as pool:
            got = [d for part in pool.map(_chunk, chunks) for d in part]
        assert got == whole


def test_gaussian_spread_and_perturbed_pose() -> None:
    model = UncertaintyModel(preset="lab")
    xs = [draw(KEY, model, i).position[0] for i in range(2000)]
    sd = math.sqrt(sum(x * x for x in xs) / len(xs))
    assert 0.0018 < sd < 0.0022
    pose = Pose(theta=1.0, phi=2.0, r=0.01, roll=0.0, pitch=0.0, yaw=0.0)
    zero = draws(KEY, UncertaintyModel(preset="none"), 1)[0]
    same = perturbed(pose, zero, 0.05)
    assert same.key() == pose.key()
    moved = perturbed(pose, draw(KEY, model, 0), 0.05)
    assert moved.key() != pose.key()
    assert abs(moved.theta - pose.theta) < math.radians(15)
