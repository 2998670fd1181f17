"""`graspscape explore OBJECT --mass --scale --units`: the object is stored through the upload's
validation, refused saying what to do, and its warnings are printed (issue #19, finding 6)."""

from __future__ import annotations

from pathlib import Path

import pytest
from graspscape.services.coordinator.errors import InvalidInput
from graspscape.services.coordinator.store.models import ObjectRow
from graspscape.services.local.cli import build_parser
from graspscape.services.local.compose import store_object
from sqlalchemy.orm import Session

from tests import object_meshes as meshes


def test_explore_takes_scale_and_units() -> None:
    args = build_parser().parse_args(["explore", "bunny.obj", "--scale", "0.5", "--units", "mm"])
    assert (args.scale, args.units) == (0.5, "mm")


def test_explore_stores_the_object_validated_and_prints_its_warnings(
    session: Session, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    tube = tmp_path / "tube.stl"
    tube.write_bytes(meshes.stl_bytes(meshes.open_tube()))
    with pytest.raises(InvalidInput, match="not watertight"):
        store_object(session, str(tube), mass_kg=0.2)
    big = tmp_path / "big.stl"
    big.write_bytes(meshes.stl_bytes(meshes.box(10_000.0)))
    with pytest.raises(InvalidInput, match="too large: 1e\\+04 m across"):
        store_object(session, str(big), mass_kg=0.2)
    # The same 10 km box said to be in millimetres is a 10 m box: still refused ...
    with pytest.raises(InvalidInput, match="too large: 10 m across at scale 1 in mm"):
        store_object(session, str(big), mass_kg=0.2, units="mm")
    # ... and scaled to 10 cm it is accepted.
    assert session.get(ObjectRow, store_object(session, str(big), mass_kg=0.2, scale=1e-5))
    two = tmp_path / "two.stl"
    two.write_bytes(meshes.stl_bytes(meshes.two_bodies()))
    capsys.readouterr()
    object_id = store_object(session, str(two), mass_kg=0.2)
    assert "warning: two.stl: mesh is 2 bodies" in capsys.readouterr().err
    assert session.get(ObjectRow, object_id).mesh_info["bodies"] == 2
    with pytest.raises(InvalidInput, match="unknown object 'pb:teapot'"):
        store_object(session, "pb:teapot")
