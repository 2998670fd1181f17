"""The wiring of the two sides, shared by every command that runs both on one machine.

`wire` gives the coordinator the workers' object preparation (its mesh for symmetry, volumes
and pictures); `open_store` and `store_object` are the first steps of `explore` and `map run`.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from graspscape.services.coordinator import db
from graspscape.services.coordinator.objects.geometry import MeshSource, use_mesh_source
from graspscape.services.coordinator.objects.schemas import ObjectOut
from graspscape.services.coordinator.objects.service import create_named, create_uploaded
from graspscape.services.coordinator.web.grasp import use_grasp_painter
from graspscape.services.local.grasp_picture import painter
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.workers.sim.evaluate import default_cache_dir
from graspscape.workers.sim.objects import prepare_object
from sqlalchemy import Engine
from sqlalchemy.orm import Session, sessionmaker


def prepared_mesh(spec: ObjectSpec) -> Any:
    """The object's mesh in its centre-of-mass frame, exactly as the workers simulate it."""
    return prepare_object(spec, default_cache_dir() / "objects").mesh


def wire() -> None:
    """Let the coordinator in this process see objects as the workers prepare them and picture
    grasps as they simulate them."""
    use_mesh_source(MeshSource(prepare=prepared_mesh, cache_dir=default_cache_dir()))
    use_grasp_painter(painter())


def open_store(url: str) -> tuple[Engine, sessionmaker[Session]]:
    """The coordinator's store at `url`, its schema brought up to date."""
    db.upgrade(url)
    engine = db.make_engine(url)
    return engine, db.make_sessionmaker(engine)


def store_object(session: Session, name_or_file: str, *, mass_kg: float | None = None,
                 friction: float | None = None, scale: float | None = None,
                 units: str | None = None) -> int:
    """Store the object to explore, a mesh file or a name (the same one twice: the first).
    It is validated as an upload is (a refusal raises, saying what to do); its warnings are
    printed to stderr."""
    props = {k: v for k, v in {"mass_kg": mass_kg, "friction": friction, "scale": scale,
                               "units": units}.items() if v is not None}
    path = Path(name_or_file)
    if path.suffix and path.is_file():
        row, _ = create_uploaded(session, filename=path.name, data=path.read_bytes(),
                                 properties=props)
    else:
        row, _ = create_named(session, name=name_or_file, properties=props, shared_dir=None)
    for message in ObjectOut.model_validate(row).warnings:
        print(f"warning: {message}", file=sys.stderr)
    return row.id
