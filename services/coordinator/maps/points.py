"""The poses a map picture draws, as arrays: lattice indices, r, μs, viability, manifold label
and robust label (manifolds/robust.py, as a small integer: ROBUST_CODES).

A picture needs of each stored pose only where it is on the lattice, its r and μs, whether it
held and its manifold label — not its grasp or signature. Read from the store (the stored
manifold table, `poses.manifold_id`), chunk by chunk into numpy arrays, that is ~40 bytes a
pose instead of a Python object graph per pose, and no regrouping of the poses on read
(measured at 199k poses before: 5.8 GB and 98 s for one `map.png`). Points are in the order
of `Point` (ring, azimuth, r index, attitude), the order the pictures have always used.
"""

from __future__ import annotations

import io
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from itertools import chain
from typing import Any

import numpy as np
from graspscape.services.coordinator.exploration.lattice import TWO_PI, Lattice
from graspscape.services.coordinator.store.models import ManifoldRow, PoseRow
from graspscape.shared.specs.pose import _KEY_DIGITS
from sqlalchemy import Select, case, func, select
from sqlalchemy.orm import Session

CHUNK = 50_000  # rows per cursor fetch
_COLUMNS = 8  # θ φ r roll pitch yaw μs, and viable/manifold/robust packed (stored_points)
_ATTITUDE_TOLERANCE = 1e-6  # as Lattice.point matches attitudes


@dataclass(frozen=True)
class MapPoints:
    """Stored lattice poses, one entry per point, sorted by (ring, azimuth, r index, attitude)."""

    ring: np.ndarray
    azimuth: np.ndarray
    r_index: np.ndarray
    attitude: np.ndarray
    r: np.ndarray
    mu_s: np.ndarray
    viable: np.ndarray
    label: np.ndarray  # manifold label, -1 for none
    robust: np.ndarray | None = None  # ROBUST_CODES of the stored robust label, -1 for none
    # What pictures derive from these points (directions, a nearest-neighbour tree per
    # attitude, the 3D view's markers: maps/render.py), kept as long as the points are (one
    # map version in picture.py's cache): the next cut of that version does not derive them
    # again. Not part of the points (a `take` starts an empty one).
    memo: dict[object, object] = field(default_factory=dict, compare=False, repr=False)

    def __len__(self) -> int:
        return len(self.ring)

    def take(self, which: np.ndarray | slice) -> MapPoints:
        """The points a mask, an index array or a slice selects."""
        return MapPoints(*(_pick(getattr(self, f), which) for f in _FIELDS))

    def directions(self, lattice: Lattice) -> np.ndarray:
        """Unit direction of every point, as `Lattice.direction` computes it (once per
        direction: many r levels and attitudes share one)."""
        if not len(self):
            return np.zeros((0, 3))
        code = self.ring.astype(np.int64) * (1 << 32) + self.azimuth
        unique, inverse = np.unique(code, return_inverse=True)
        dirs = np.array([_direction(lattice, int(c >> 32), int(c & 0xFFFFFFFF)) for c in unique])
        return dirs[inverse.ravel()]


def _direction(lattice: Lattice, ring: int, azimuth: int) -> tuple[float, float, float]:
    """`lattice.direction` of a point of that ring and azimuth, the same arithmetic without
    making its Pose (a validated model: most of the cost of ~40k directions at 1M poses)."""
    theta = lattice.theta(ring)
    phi = 0.0 if lattice.is_pole(ring) else azimuth * TWO_PI / lattice.m(ring)
    st = math.sin(theta)
    return (st * math.cos(phi), st * math.sin(phi), math.cos(theta))


_FIELDS = ("ring", "azimuth", "r_index", "attitude", "r", "mu_s", "viable", "label", "robust")
# The robust labels as the pictures code them (-1: not computed yet).
ROBUST_CODES = {"robust": 0, "uncertain": 1, "fragile": 2, "futile": 3}


def _pick(values: np.ndarray | None, which: np.ndarray | slice) -> np.ndarray | None:
    return None if values is None else values[which]


def _lattice_indices(lattice: Lattice, cols: np.ndarray) -> tuple[np.ndarray, ...]:
    """(K, J, I, a, on_lattice) of stored poses (columns θ φ r roll pitch yaw), as
    `samples.point_or_none` finds them: by rounding, then kept only where the point's pose has
    the pose's key (every coordinate equal to _KEY_DIGITS digits)."""
    theta, phi, r, roll, pitch, yaw = cols.T
    n_rings = lattice.n_rings
    K = np.clip(np.rint(theta * n_rings / math.pi).astype(np.int64), 0, n_rings)
    m = np.array([lattice.m(k) for k in range(n_rings + 1)], dtype=np.int64)[K]
    J = np.where(m == 1, 0, np.rint(np.mod(phi, TWO_PI) * m / TWO_PI).astype(np.int64) % m)
    I = np.rint((r - lattice.grid.r_min) / lattice.dr(lattice.depth)).astype(np.int64)  # noqa: E741
    att = np.full(len(cols), -1, dtype=np.int64)
    for a, (ra, pa, ya) in reversed(list(enumerate(lattice.attitudes))):
        d = np.mod(roll, TWO_PI) - ra
        d = d - TWO_PI * np.rint(d / TWO_PI)
        hit = ((np.abs(d) < _ATTITUDE_TOLERANCE) & (np.abs(pitch - pa) < _ATTITUDE_TOLERANCE)
               & (np.abs(yaw - ya) < _ATTITUDE_TOLERANCE))
        att[hit] = a  # reversed: the first matching attitude wins, as in Lattice.point
    pole = (K == 0) | (n_rings == K)
    lat_theta = K * math.pi / n_rings
    lat_phi = np.where(pole, 0.0, J * TWO_PI / m)
    lat_r = np.round(lattice.grid.r_min + I * lattice.dr(lattice.depth), 9)

    def same(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.round(a, _KEY_DIGITS) == np.round(b, _KEY_DIGITS)

    # The key puts φ = 0 within 10^-digits of a pole, as the lattice does at one.
    near_pole = (theta < 10.0**-_KEY_DIGITS) | (math.pi - theta < 10.0**-_KEY_DIGITS)
    stored_phi = np.where(near_pole, 0.0, np.mod(phi, TWO_PI))
    on = (att >= 0) & same(theta, lat_theta) & same(stored_phi, lat_phi) & same(r, lat_r)
    return K, J, I, att, on


def _row_chunks(session: Session, query: Select[Any], chunk: int) -> Iterator[list[Any]]:
    """Plain tuples from the driver, `chunk` at a time, from a server-side cursor on
    PostgreSQL: SQLAlchemy's row objects cost more than the rest of a picture at 1M poses
    (the query has no parameters but the exploration id, inlined as a literal integer)."""
    dialect = session.get_bind().dialect
    sql = str(query.compile(dialect=dialect, compile_kwargs={"literal_binds": True}))
    driver = session.connection().connection.driver_connection
    postgres = dialect.name == "postgresql"
    cursor = driver.cursor(name="map_points") if postgres else driver.cursor()  # type: ignore[union-attr]
    try:
        cursor.execute(sql)
        while rows := cursor.fetchmany(chunk):
            yield rows
    finally:
        cursor.close()


def stored_points(session: Session, exploration_id: int, lattice: Lattice) -> MapPoints:
    """The exploration's stored lattice poses with their stored manifold labels."""
    label_of_id = {mid: label for mid, label in session.execute(
        select(ManifoldRow.id, ManifoldRow.label).where(
            ManifoldRow.exploration_id == exploration_id))}
    # Viability, manifold id and robust code packed into one integer column: each value of a
    # row read is a Python object made by the driver, the bulk of a read at 1M poses.
    robust = case(*((PoseRow.robust_label == name, code) for name, code in ROBUST_CODES.items()),
                  else_=-1)
    packed = (func.coalesce(PoseRow.manifold_id, 0) * 8 + robust + 1) * 2 + case(
        (PoseRow.viable, 1), else_=0)
    query = select(
        PoseRow.theta, PoseRow.phi, PoseRow.r, PoseRow.roll, PoseRow.pitch, PoseRow.yaw,
        PoseRow.mu_s, packed,
    ).where(PoseRow.exploration_id == int(exploration_id))
    parts: list[MapPoints] = []
    ids = np.array([0, *label_of_id], dtype=np.int64)  # 0: no manifold
    order = np.argsort(ids)
    ids, labels = ids[order], np.array([-1, *label_of_id.values()], dtype=np.int64)[order]
    for rows in _row_chunks(session, query, CHUNK):
        # One pass over the rows' values (np.array of a list of tuples costs ~2x); doubles
        # hold the packed integers exactly (ids below 2^49).
        arr = np.fromiter(chain.from_iterable(rows), dtype=np.float64,
                          count=len(rows) * _COLUMNS).reshape(len(rows), _COLUMNS)
        K, J, I, att, on = _lattice_indices(lattice, arr[:, :6])  # noqa: E741
        code = arr[:, 7].astype(np.int64)
        label = labels[np.searchsorted(ids, code >> 4)]
        parts.append(MapPoints(K[on], J[on], I[on], att[on], arr[on, 2], arr[on, 6],
                               (code[on] & 1) != 0, label[on], ((code[on] >> 1) & 7) - 1))
    if not parts:
        empty = np.zeros(0, dtype=np.int64)
        return MapPoints(empty, empty, empty, empty, np.zeros(0), np.zeros(0),
                         np.zeros(0, dtype=bool), empty, empty)
    whole = MapPoints(*(np.concatenate([getattr(p, f) for p in parts]) for f in _FIELDS))
    return whole.take(_point_order(whole))


def points_bytes(points: MapPoints, extra: Mapping[str, np.ndarray] | None = None) -> bytes:
    """The points as stored beside a drawn-ahead picture (maps/stored.py): each array in an
    uncompressed `.npz`, integers in the smallest type that holds their values (27 MB for the
    1M-pose bench map, ~26 bytes a point instead of ~65), read back by `points_from_bytes` as
    the same values and dtypes; `extra`: arrays stored with them as they are (what pictures
    derive from the points: maps/derived.packed), given back by `unpacked`."""
    arrays: dict[str, np.ndarray] = {}
    for name in _FIELDS:
        values = getattr(points, name)
        if values is None:
            continue
        if values.dtype.kind == "i" and len(values):
            values = values.astype(np.result_type(np.min_scalar_type(int(values.min())),
                                                  np.min_scalar_type(int(values.max()))))
        arrays[name] = values
        arrays[f"{name}.dtype"] = np.array(getattr(points, name).dtype.str)
    for name, values in (extra or {}).items():
        arrays[f"{_EXTRA}{name}"] = values
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return buffer.getvalue()


_EXTRA = "extra."


def points_from_bytes(data: bytes) -> MapPoints:
    """The points `points_bytes` stored, in their first dtypes (a cast back is exact)."""
    return unpacked(data)[0]


def unpacked(data: bytes) -> tuple[MapPoints, dict[str, np.ndarray]]:
    """The points `points_bytes` stored and the `extra` arrays stored with them."""
    with np.load(io.BytesIO(data), allow_pickle=False) as stored:
        values = {name: stored[name].astype(str(stored[f"{name}.dtype"]), copy=False)
                  for name in _FIELDS if name in stored.files}
        extra = {name.removeprefix(_EXTRA): stored[name] for name in stored.files
                 if name.startswith(_EXTRA)}
    return MapPoints(**values), extra


def _point_order(pts: MapPoints) -> np.ndarray:
    """The stable sort by (ring, azimuth, r index, attitude): one int64 key where the indices
    fit (a stable argsort of it is lexsort's order, at a third of its cost at 1M poses)."""
    if not len(pts):
        return np.zeros(0, dtype=np.int64)
    columns = [pts.ring, pts.azimuth, pts.r_index, pts.attitude]
    spans = [int(c.max()) + 1 for c in columns]
    if min(int(c.min()) for c in columns) < 0 or math.prod(spans) >= 2**62:
        return np.lexsort(columns[::-1])
    code = np.zeros(len(pts), dtype=np.int64)
    for column, span in zip(columns, spans, strict=True):
        code = code * span + column
    return np.argsort(code, kind="stable")
