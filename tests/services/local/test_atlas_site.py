"""The atlas site's 3D view data (view3d-data.js, read by the bundled viewer atlas3d.js as a
classic script, since pages opened from disk can fetch nothing): every viable approach
direction with its manifold label, and the mesh where one could be exported. An oracle
exploration stands in for physics. The slow browser test writes a whole site and opens it
from file:// (tests/services/coordinator/web/test_atlas_browser.py)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from graspscape.services.coordinator.manifolds import service as manifolds
from graspscape.services.coordinator.store.models import ManifoldRow, PoseRow
from graspscape.services.local.atlas_site import write_3d_data
from graspscape.services.local.compose import store_object
from graspscape.shared.specs.exploration import ExplorationSpec, PoseGridSpec, RefinementSpec
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from tests.factories import explore_with_oracle

PREFIX = "window.GRASPSCAPE_ATLAS_3D = "


def oracle_sphere(sessions: sessionmaker[Session], dtheta_deg: float = 60) -> int:
    """A sphere explored with the oracle (two grasp types split at φ = π), manifolds grouped."""
    with sessions() as s:
        object_id = store_object(s, "sphere")
    spec = ExplorationSpec(object_id=object_id, grid=PoseGridSpec(
        dtheta=math.radians(dtheta_deg), r_min=0.01, r_max=0.02, dr=0.01),
        refinement=RefinementSpec(levels=0))
    eid, _, _ = explore_with_oracle(sessions, spec)
    with sessions() as s:
        manifolds.ensure_manifolds(s, eid)
    return eid


def read_data(path: Path) -> dict[str, Any]:
    text = path.read_text().rstrip()
    assert text.startswith(PREFIX) and text.endswith(";")
    return json.loads(text[len(PREFIX):-1])


def test_3d_data_is_every_viable_direction_with_its_manifold(
        sqlite_sessions: sessionmaker[Session], tmp_path: Path) -> None:
    eid = oracle_sphere(sqlite_sessions)
    with sqlite_sessions() as s:
        write_3d_data(s, eid, tmp_path, exports=[])
        viable = s.execute(select(PoseRow.id, PoseRow.theta, PoseRow.phi, ManifoldRow.label)
                           .join(ManifoldRow, ManifoldRow.id == PoseRow.manifold_id)
                           .where(PoseRow.exploration_id == eid, PoseRow.viable.is_(True))
                           .order_by(PoseRow.id)).all()
    data = read_data(tmp_path / "view3d-data.js")
    d = data["directions"]
    assert d["total_viable"] == len(viable) > 0
    assert d["pose_id"] == [v.id for v in viable]
    assert d["theta"] == [v.theta for v in viable] and d["phi"] == [v.phi for v in viable]
    # Coloured by manifold: the oracle's two grasp types are two labels here.
    assert d["label"] == [v.label for v in viable] and len(set(d["label"])) == 2
    assert data["obj"] is None  # no object.obj export beside it: no mesh, the markers only


def test_3d_data_carries_the_exported_mesh(sqlite_sessions: sessionmaker[Session],
                                           tmp_path: Path) -> None:
    eid = oracle_sphere(sqlite_sessions, dtheta_deg=90)
    # The export as atlas_site writes it beside the page (here a hand-made OBJ with "</" in a
    # comment: the data file must stay one script whatever the mesh text holds).
    obj = "# made by a test </script>\nv 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nf 1 2 3\n"
    (tmp_path / "object.obj").write_text(obj)
    with sqlite_sessions() as s:
        write_3d_data(s, eid, tmp_path, exports=["object.obj"])
    text = (tmp_path / "view3d-data.js").read_text()
    assert "</script>" not in text
    assert read_data(tmp_path / "view3d-data.js")["obj"] == obj


def test_the_sites_graspgen_names_the_mesh_beside_it(sqlite_sessions: sessionmaker[Session],
                                                     tmp_path: Path) -> None:
    import trimesh
    from graspscape.services.local.atlas_site import _write_exports

    eid = oracle_sphere(sqlite_sessions, dtheta_deg=90)
    with sqlite_sessions() as s:
        written = _write_exports(s, eid, tmp_path)
    assert {"object.obj", "graspgen.json"} <= set(written)
    data = json.loads((tmp_path / "graspgen.json").read_text())
    assert data["object"]["file"] == "object.obj"
    mesh = trimesh.load(tmp_path / data["object"]["file"], force="mesh")
    assert len(mesh.faces) > 0 and mesh.is_watertight
