"""One exploration's map picture and manifold table, straight from the store (used by the
`map show` command and by `explore` when it finishes)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Literal

from sqlalchemy.orm import Session


def write_map_files(session: Session, exploration_id: int, picture: Path,
                    table: Path | None = None, *, cut: Literal["horizontal", "vertical"] =
                    "horizontal", phi0_deg: float = 0.0, attitude: int = 0) -> tuple[int, int]:
    """Writes the map (PNG or SVG by suffix) and optionally the manifold table (JSON);
    returns (manifolds, poses)."""
    from graspscape.services.coordinator.manifolds.service import current_map, stored_manifolds
    from graspscape.services.coordinator.maps.render import render_map

    computed = current_map(session, exploration_id)
    fmt = "svg" if picture.suffix.lower() == ".svg" else "png"
    picture.write_bytes(render_map(
        computed.lattice, computed.samples, computed.label_of, computed.map, computed.mesh,
        cut=cut, phi0=math.radians(phi0_deg), attitude=attitude, fmt=fmt,
        title=f"{computed.spec.label or ''}".strip()))
    if table is not None:
        items = stored_manifolds(session, exploration_id)
        table.write_text(json.dumps([m.model_dump(mode="json") for m in items], indent=2))
    return len(computed.map.manifolds), len(computed.samples)
