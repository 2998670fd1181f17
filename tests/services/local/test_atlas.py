"""`graspscape atlas`: which objects it explores, that a finished object is skipped and an
unfinished one resumed (found by its spec), and (slow) a real two-object atlas on a tiny grid
whose static site opens from disk, run twice: the second run explores nothing."""

from __future__ import annotations

import csv
import json
import os
import shutil
import time
from pathlib import Path

import pytest
from graspscape.services.coordinator.settings import Settings
from graspscape.services.coordinator.store.models import ExplorationRow
from graspscape.services.local.atlas import (
    DEFAULT_OBJECTS,
    SETTINGS,
    AtlasOptions,
    _find_or_create,
    atlas_objects,
    run_atlas,
)
from graspscape.services.local.cli import build_parser
from graspscape.services.local.compose import store_object, wire
from graspscape.shared.specs.object_names import BUILTIN_NAMES, ycb_root
from sqlalchemy.orm import Session

from tests import object_meshes as meshes
from tests.services.local.test_atlas_site import read_data


def test_objects_are_the_builtins_ycb_folders_and_mesh_files(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("GRASPSCAPE_YCB_DIR", raising=False)
    for folder in ("YcbA", "YcbB"):
        (tmp_path / "ycb" / folder).mkdir(parents=True)
        (tmp_path / "ycb" / folder / "model.urdf").write_text("<robot/>")
    (tmp_path / "ycb" / "NotAnObject").mkdir()
    (tmp_path / "box.stl").write_bytes(b"solid")
    (tmp_path / "notes.txt").write_text("")
    names = atlas_objects(tmp_path)
    assert names == [*BUILTIN_NAMES, "ycb:YcbA", "ycb:YcbB", str(tmp_path / "box.stl")]
    # The default folder is the one `ycb:` names resolve from.
    assert ycb_root() == DEFAULT_OBJECTS / "ycb"
    args = build_parser().parse_args(["atlas", "--only", "mug", "--only", "cube", "--procs", "0"])
    assert (args.only, args.procs, args.setting) == (["mug", "cube"], 0, None)


def test_finished_exploration_is_skipped_unfinished_resumed(session: Session,
                                                            tmp_path: Path) -> None:
    settings = Settings(database={"url": "sqlite://", "data_dir": tmp_path})
    object_id = store_object(session, "sphere")
    spec = SETTINGS["reduced"].spec(object_id, "sphere")
    [(first, finished, resting)] = _find_or_create(session, spec, settings)
    assert not finished and resting is None
    [(again, finished, _)] = _find_or_create(session, spec, settings)
    assert (again, finished) == (first, False)  # unfinished: resumed, not created twice
    row = session.get(ExplorationRow, first)
    row.status = "done"
    session.commit()
    assert _find_or_create(session, spec, settings) == [(first, True, None)]
    other = SETTINGS["full"].spec(object_id, "sphere")
    assert _find_or_create(session, other, settings)[0][0] != first  # another setting: new


def test_on_a_table_one_exploration_per_resting_pose_found_again(session: Session,
                                                                 tmp_path: Path) -> None:
    settings = Settings(database={"url": "sqlite://", "data_dir": tmp_path})
    wire()  # the workers' object preparation: the cube's mesh, for its resting poses
    cube = store_object(session, "cube")
    setting = SETTINGS["reduced"].model_copy(update={"support": "plane"})
    spec = setting.spec(cube, "cube")
    assert spec.support.kind == "plane"
    group = _find_or_create(session, spec, settings)
    # A cube rests on any of its six faces alike: the four most probable are explored.
    assert len(group) == 4
    assert [resting.index for _, _, resting in group] == [0, 1, 2, 3]
    rows = [session.get(ExplorationRow, eid) for eid, _, _ in group]
    assert {row.support_group for row in rows} == {group[0][0]}
    assert _find_or_create(session, spec, settings) == group  # found again, not created
    free = SETTINGS["reduced"].spec(cube, "cube")
    assert _find_or_create(session, free, settings)[0][0] not in {eid for eid, _, _ in group}
    args = build_parser().parse_args(["atlas", "--support", "plane", "--only", "cube"])
    assert args.support == "plane"


@pytest.mark.slow
def test_two_objects_tiny_grid_site_from_disk(tmp_path: Path) -> None:
    objects = tmp_path / "objects"
    objects.mkdir()
    (objects / "box.stl").write_bytes(meshes.stl_bytes(meshes.box(0.06)))
    ycb_env = os.environ.get("GRASPSCAPE_YCB_DIR")
    opts = AtlasOptions(objects_dir=objects, only=("sphere", "box"), data_dir=tmp_path / "data",
                        out=tmp_path / "site", procs=1, grid_override_deg=90)
    assert run_atlas(opts) == 0
    site = json.loads((tmp_path / "site" / "atlas.json").read_text())
    by_name = {o["name"]: o for o in site["objects"]}
    assert set(by_name) == {"sphere", "box"}
    for o in by_name.values():
        assert o["status"] == "done" and o["poses"] > 0 and o["manifolds"] >= 1
        assert o["wall_s"] > 0 and not o["skipped"]
        page = (tmp_path / "site" / o["folder"] / "index.html").read_text()
        assert "map-horizontal.png" in page and "grasp-A.png" in page
        for name in ("map-horizontal.png", "map-vertical.png", "poses.csv", "object.obj",
                     "manifolds.json", "grasp-A.png"):
            assert (tmp_path / "site" / o["folder"] / name).stat().st_size > 0
        lines = (tmp_path / "site" / o["folder"] / "poses.csv").read_text().splitlines()
        assert len(lines) == o["poses"] + 1
        # The 3D view's data: the real mesh as exported and every viable direction.
        data = read_data(tmp_path / "site" / o["folder"] / "view3d-data.js")
        assert data["obj"] == (tmp_path / "site" / o["folder"] / "object.obj").read_text()
        viable = sum(row["viable"] == "True" for row in csv.DictReader(lines))
        assert data["directions"]["total_viable"] == viable
        assert 'src="../atlas3d.js"' in page
    assert (tmp_path / "site" / "atlas3d.js").stat().st_size > 100_000
    # Links are relative: the site works from any folder (moved here, nothing breaks).
    moved = tmp_path / "moved"
    shutil.copytree(tmp_path / "site", moved)
    index = (moved / "index.html").read_text()
    assert 'href="sphere/index.html"' in index and "http" not in index
    # Resumable: a second run finds both done and explores nothing.
    started = time.monotonic()
    assert run_atlas(opts.model_copy(update={"pictures": False})) == 0
    again = json.loads((tmp_path / "site" / "atlas.json").read_text())
    assert all(o["skipped"] for o in again["objects"])
    assert [o["exploration_id"] for o in again["objects"]] == \
        [o["exploration_id"] for o in site["objects"]]
    assert time.monotonic() - started < 300
    assert os.environ.get("GRASPSCAPE_YCB_DIR") == ycb_env  # restored after the run


@pytest.mark.slow
def test_cube_on_a_table_one_page_per_resting_pose(tmp_path: Path) -> None:
    opts = AtlasOptions(objects_dir=tmp_path, only=("cube",), data_dir=tmp_path / "data",
                        out=tmp_path / "site", procs=1, grid_override_deg=90, support="plane",
                        pictures=False)
    assert run_atlas(opts) == 0
    site = json.loads((tmp_path / "site" / "atlas.json").read_text())
    assert site["setting"]["support"] == "plane"
    objects = site["objects"]
    assert [o["name"] for o in objects] == [f"cube rest{k}" for k in range(4)]
    assert [o["resting_index"] for o in objects] == [0, 1, 2, 3]
    assert sum(o["resting_probability"] for o in objects) == pytest.approx(4 / 6, abs=0.1)
    for o in objects:
        assert o["status"] == "done" and o["poses"] > 0
        page = (tmp_path / "site" / o["folder"] / "index.html").read_text()
        assert 'data-field="resting"' in page
        data = read_data(tmp_path / "site" / o["folder"] / "view3d-data.js")
        # The 3D view's table: the cube (6 cm) rests with its centre 3 cm above it.
        assert data["resting"]["index"] == o["resting_index"]
        assert data["resting"]["position"][2] == pytest.approx(0.03, abs=1e-3)
    index = (tmp_path / "site" / "index.html").read_text()
    assert "on a table" in index and 'href="cube_rest0/index.html"' in index
