"""Pose keys: one key per point of the pose space, whatever path computed its coordinates.

The key is what the store dedupes on and what the coordinator checks a worker's batch
against, so two computations of one grid point must agree and two distinct points must not.
"""

from __future__ import annotations

import math

from graspscape.shared.specs.pose import Pose, pose_key, tile_pose_keys, tile_poses
from hypothesis import given
from hypothesis import strategies as st

TAU = 2 * math.pi
thetas = st.floats(0.0, math.pi)
phis = st.floats(-20.0, 20.0)
rs = st.floats(0.0, 0.2)
rolls = st.floats(-20.0, 20.0)
pitches = st.floats(-1.0, 1.0)


def _coords(key: str) -> list[float]:
    return [float(v) for v in key.split("/")]


@given(thetas, phis, rs, rolls, pitches)
def test_azimuth_and_roll_wrap_to_one_key(theta, phi, r, roll, pitch) -> None:
    key = pose_key(theta, phi, r, roll, pitch)
    for turns in (-2, -1, 1, 3):
        wrapped = pose_key(theta, phi + turns * TAU, r, roll - turns * TAU, pitch)
        a, b = _coords(key), _coords(wrapped)
        # wrapping may carry a value across the rounding boundary at 2π ≡ 0 and nowhere else
        for i in (1, 3):
            assert abs(math.remainder(a[i] - b[i], TAU)) <= 2e-6
        assert a[0] == b[0] and a[2] == b[2] and a[4] == b[4]


@given(phis, rs, rolls)
def test_every_azimuth_at_a_pole_is_one_point(phi, r, roll) -> None:
    for pole in (0.0, math.pi):
        assert pose_key(pole, phi, r, roll) == pose_key(pole, 0.0, r, roll)


def test_negative_zero_and_tiny_noise_give_the_grid_point_key() -> None:
    assert pose_key(-0.0, 0.0, -0.0, -0.0, -0.0, -0.0) == pose_key(0.0, 0.0, 0.0)
    exact = pose_key(math.pi / 3, math.pi / 4, 0.01, math.pi / 2)
    noisy = pose_key(math.pi / 3 + 1e-9, math.pi / 4 - 1e-9, 0.01 + 1e-10, math.pi / 2 + 1e-9)
    assert exact == noisy
    assert "-" not in pose_key(1.0, 1e-12 - TAU, 0.0, -1e-12)


@given(thetas, phis, rs, rolls, pitches)
def test_a_key_gives_back_its_pose_within_the_rounding(theta, phi, r, roll, pitch) -> None:
    pose = Pose(theta=theta, phi=phi, r=r, roll=roll, pitch=pitch)
    back = _coords(pose.key())
    assert abs(back[0] - theta) <= 5e-7 and abs(back[2] - r) <= 5e-7
    assert abs(back[4] - pitch) <= 5e-7
    if 1e-6 < theta < math.pi - 1e-6:
        assert abs(math.remainder(back[1] - phi, TAU)) <= 5e-7
    assert abs(math.remainder(back[3] - roll, TAU)) <= 5e-7
    assert 0.0 <= back[1] <= TAU and 0.0 <= back[3] <= TAU


def test_the_points_of_a_fine_grid_have_distinct_keys() -> None:
    step = math.radians(1.0)
    cells = [(k * step, j * step) for k in range(1, 180) for j in range(0, 360, 7)]
    keys = tile_pose_keys(cells, [0.0, 0.0025, 0.005], [(0.0, 0.0, 0.0), (math.pi / 8, 0, 0)])
    assert len(set(keys)) == len(keys) == len(cells) * 3 * 2


@given(st.lists(st.tuples(thetas, phis), min_size=1, max_size=5),
       st.lists(rs, min_size=1, max_size=3),
       st.lists(st.tuples(rolls, pitches, st.just(0.0)), min_size=1, max_size=3))
def test_tile_keys_equal_the_keys_of_the_tiles_poses(cells, r_levels, attitudes) -> None:
    assert tile_pose_keys(cells, r_levels, attitudes) == [
        p.key() for p in tile_poses(cells, r_levels, attitudes)
    ]
