"""The stored pose as the map and the strategies read it (`StoredPose`, from a pose row), and
the one pose shape every pose the API returns carries (`PoseValues`)."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from pydantic import BaseModel, Field

_LINK = re.compile(r"^([A-Za-z]+)_(?:\d+|spread|pad)$")


def digit(link: str) -> str:
    """The finger a link belongs to ("B_2" and the scissor base "B_spread" → "B"), or the
    link itself ("palm")."""
    match = _LINK.match(link)
    return match.group(1) if match else link


@dataclass(frozen=True)
class StoredPose:
    """A stored pose as the map and the strategies read it: its result, and of its grasp the
    digits in contact, their contact centroids and the joint angles."""

    key: str
    theta: float
    phi: float
    r: float
    roll: float
    pitch: float
    yaw: float
    viable: bool
    outcome: str
    mu_s: float
    effort: float = 0.0
    digits: frozenset[str] = frozenset()
    # digit → force-weighted contact centroid in the object frame
    contacts: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    joints: dict[str, float] = field(default_factory=dict)
    grasp: dict[str, Any] | None = None
    source: str = "evaluated"  # or "shortcut:normal", "shortcut:configuration", "shortcut:symmetry"
    # A draw's outcome and digits in contact per engine (its stored `sample` record, an
    # outcome-only evaluation); empty for every other pose.
    engines: dict[str, tuple[bool, frozenset[str]]] = field(default_factory=dict)

    @staticmethod
    def from_row(row: Any) -> StoredPose:
        """From a stored pose row (columns as attributes), or from the column mapping of a
        row about to be stored (the shortcuts' copies)."""
        get = row.get if isinstance(row, Mapping) else lambda name: getattr(row, name, None)
        digits: dict[str, list[tuple[tuple[float, float, float], float]]] = {}
        sig = get("signature") or {}
        for c in sig.get("contacts", ()):
            digits.setdefault(digit(c["link"]), []).append(
                (tuple(c["position_object"]), max(float(c["normal_force_n"]), 0.0))
            )
        for link in sig.get("links_in_contact", ()):
            digits.setdefault(digit(link), [])
        contacts = {}
        for d, items in digits.items():
            if not items:
                continue
            total = sum(w for _, w in items)
            ws = [w / total if total > 0 else 1 / len(items) for _, w in items]
            contacts[d] = tuple(
                sum(w * pos[i] for (pos, _), w in zip(items, ws, strict=True)) for i in range(3)
            )
        return StoredPose(
            key=get("pose_key"),
            theta=get("theta"),
            phi=get("phi"),
            r=get("r"),
            roll=get("roll"),
            pitch=get("pitch"),
            yaw=get("yaw"),
            viable=bool(get("viable")),
            outcome=get("outcome"),
            mu_s=float(get("mu_s")),
            effort=float(get("effort_max_nm") or 0.0),
            digits=frozenset(digits),
            contacts=contacts,  # type: ignore[arg-type]
            joints={k: float(v) for k, v in (sig.get("joint_angles") or {}).items()},
            grasp=get("grasp"),
            source=source_of(get("worker_id"), get("inferred_from")),
            engines=engine_outcomes(get("sample")),
        )

    def direction(self) -> tuple[float, float, float]:
        st = math.sin(self.theta)
        return (st * math.cos(self.phi), st * math.sin(self.phi), math.cos(self.theta))


def engine_outcomes(record: Mapping[str, Any] | None) -> dict[str, tuple[bool, frozenset[str]]]:
    """A stored draw record's (PoseResult.sample) held flag and digits in contact by engine."""
    if not record:
        return {}
    return {name: (e.get("outcome") == "held", frozenset(digit(x) for x in e.get("links", ())))
            for name, e in (record.get("engines") or {}).items()}


def source_of(worker_id: str | None, inferred_from: str | None) -> str:
    """How a stored pose was obtained: "evaluated" (simulated through), or the shortcut that
    supplied its result ("shortcut:normal" or "shortcut:symmetry" copied by the coordinator,
    "shortcut:configuration" synthesized by a worker, trajectory outcome reused)."""
    worker = worker_id or ""
    if worker.startswith("shortcut:"):
        return worker
    if inferred_from:
        return "shortcut:configuration"
    return "evaluated"


class PoseValues(BaseModel):
    """Where a pose is and its headline result: the one pose shape that every pose the API
    returns carries (`PoseOut`, a stored pose in full, in /poses and /best; `PoseBrief`, a
    manifold's best pose and local maxima, in the manifold routes and the table export)."""

    theta: float = Field(description="polar angle of the approach direction from +z, rad")
    phi: float = Field(description="azimuth of the approach direction, rad")
    r: float = Field(description="start gap between palm and object surface, m")
    roll: float = Field(description="roll about the palm normal, rad")
    pitch: float
    yaw: float
    mu_s: float = Field(description="the simulated grasp's μs (0 where it failed)")
    effort_max_nm: float = Field(description="largest joint effort of the grasp, N·m")
