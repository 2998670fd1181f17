"""The exploration page in headless Chromium against the real app (uvicorn on loopback,
SQLite) holding an exploration stored through the real ingest: the table lists the large
manifolds and the dust as one collapsed row, its headers say their units, the chosen grasp
opens beside the map in view with the curated numbers (the raw fields behind a toggle), and
no ETA is shown for a finished run or before one can be estimated."""

from __future__ import annotations

import math
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from graspscape.services.coordinator import db
from graspscape.services.coordinator.app import create_app
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.manifolds.service import ensure_manifolds
from graspscape.services.coordinator.settings import Settings
from graspscape.services.local.compose import store_object, wire
from graspscape.services.local.run import run_local
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.results import GraspSignature

from tests.factories import oracle_result
from tests.live_server import serving

pytestmark = pytest.mark.slow

def _with_dust(poses, match=None):  # type: ignore[no-untyped-def]
    """The oracle's two grasp types, and here and there an isolated pose held with two
    fingers only: single-pose manifolds, the dust."""
    out = []
    for p in poses:
        r = oracle_result(p)
        if r.viable and zlib.crc32(p.key().encode()) % 23 == 0:
            links = ("A_3", "B_3")
            r = r.model_copy(update={"signature": GraspSignature(
                links_in_contact=links, contacts=tuple(
                    c for c in r.signature.contacts if c.link in links),
                joint_angles=r.signature.joint_angles)})
        out.append(r)
    return out


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    folder = tmp_path_factory.mktemp("page")
    url = f"sqlite:///{folder / 'coordinator.db'}"
    db.upgrade(url)
    wire()
    engine = db.make_engine(url)
    sessions = db.make_sessionmaker(engine)
    spec = {"strategy": {"name": "grid"}, "refinement": {"levels": 0},
            "settings": {"robustness": {"tests": []}},
            "grid": {"dtheta": math.radians(20), "r_min": 0.01, "r_max": 0.02, "dr": 0.01}}
    with sessions() as s:
        obj = store_object(s, "sphere")
        done = create_exploration(s, spec=ExplorationSpec(object_id=obj, label="page sphere",
                                                          **spec),
                                  tile_target_poses=50, max_poses=10**6).id
    run_local(sessions, _with_dust)
    with sessions() as s:
        ensure_manifolds(s, done)
        queued = create_exploration(s, spec=ExplorationSpec(object_id=obj, label="waiting",
                                                            **spec),
                                    tile_target_poses=50, max_poses=10**6).id
        # The sphere on a table: one resting pose, queued (the 3D view needs no poses).
        table = create_exploration(s, spec=ExplorationSpec(
            object_id=obj, label="on a table", support={"kind": "plane"}, **spec),
            tile_target_poses=50, max_poses=10**6)
        table_height = table.spec["support"]["resting"]["position"][2]
        table = table.id
    settings = Settings(database={"url": url, "data_dir": folder},
                        api={"token": None}, queue={"requeue_interval_s": 3600})
    with serving(create_app(settings), start_timeout_s=60) as base:
        yield {"base": base, "done": done, "queued": queued, "table": table,
               "table_height": table_height}
        engine.dispose()


def _open(p: Any, served: dict[str, Any], which: str) -> None:
    p.goto(f"{served['base']}/#/exploration/{served[which]}")
    p.get_by_test_id("manifolds").wait_for()


def test_large_manifolds_and_one_dust_row(served, page) -> None:
    p, console = page
    _open(p, served, "done")
    table = p.get_by_test_id("manifolds")
    heads = table.locator("thead th").all_inner_texts()
    assert "Volume, cm³" in heads and "Robust core, cm³" in heads
    assert "P(success)" in heads
    # Each large manifold's cell says what /manifolds' `success` says: k/n and the bounds, or
    # "–" where its best grasp was never drawn.
    cell = table.get_by_test_id("success-A").inner_text()
    assert cell == "–" or "/" in cell
    assert not any("_" in h for h in heads)  # no raw field names
    shown = table.locator("tbody tr:visible")
    names = [n for n in shown.locator("th").all_inner_texts()]
    assert names[-1] == "Dust" and names[:2] == ["A", "B"]
    dust = table.locator("tr.dust")
    assert dust.count() >= 2 and dust.first.is_hidden()
    toggle = p.get_by_test_id("dust-toggle")
    assert toggle.get_attribute("aria-expanded") == "false"
    toggle.click()
    assert dust.first.is_visible() and toggle.get_attribute("aria-expanded") == "true"
    assert p.get_by_test_id("dust").inner_text().count("smaller manifolds") == 1
    toggle.click()
    assert dust.first.is_hidden()
    assert console.errors == []


def test_the_chosen_grasp_opens_beside_the_map(served, page) -> None:
    p, console = page
    _open(p, served, "done")
    p.get_by_test_id("best-A").click()
    panel = p.get_by_test_id("grasp")
    panel.locator("[data-field=mu_s]").wait_for()
    box, the_map = panel.bounding_box(), p.locator("section.map").bounding_box()
    assert box["x"] >= the_map["x"] + the_map["width"]  # beside it, not below the table
    # Its numbers in view where the button was clicked (it was below the whole table).
    height = p.viewport_size["height"]
    for seen in (panel.locator("[data-field=mu_s]"), p.get_by_test_id("best-A")):
        box = seen.bounding_box()
        assert box["y"] >= 0 and box["y"] + box["height"] <= height, seen
    numbers = panel.get_by_test_id("grasp-numbers").inner_text()
    assert "Start gap" in numbers and " mm" in numbers and "°" in numbers
    raw = panel.get_by_test_id("raw-fields")
    assert raw.locator("[data-raw=pose_key]").is_hidden()
    raw.locator("summary").click()
    assert raw.locator("[data-raw=pose_key]").is_visible()
    assert console.errors == []


def test_no_eta_when_finished_or_not_yet_estimable(served, page) -> None:
    p, console = page
    _open(p, served, "done")
    facts = p.get_by_test_id("facts")
    text = facts.inner_text()
    assert "done" in text and "time left" not in text and "per second" not in text
    _open(p, served, "queued")
    p.get_by_test_id("facts").locator("[data-field=eta]").wait_for()
    assert "estimating" in p.get_by_test_id("facts").inner_text()
    p.goto(served["base"] + "/")
    row = p.get_by_test_id(f"exploration-{served['done']}")
    row.wait_for()
    assert row.locator("[data-field=eta]").inner_text() == "–"
    assert console.errors == []


def test_the_3d_view_draws_the_table_only_on_a_table(served, page) -> None:
    p, console = page
    _open(p, served, "table")
    canvas = p.locator("#view3d[data-table]")
    canvas.wait_for()
    # The table's plane lies its resting height under the centre of mass (a sphere: its radius).
    assert float(canvas.get_attribute("data-table")) == pytest.approx(
        served["table_height"], abs=1e-4)
    assert served["table_height"] == pytest.approx(0.04, abs=2e-3)
    _open(p, served, "done")
    p.locator("#view3d[data-points]").wait_for()
    assert p.locator("#view3d").get_attribute("data-table") is None
    assert console.errors == []


def test_screenshot(served, page, tmp_path: Path) -> None:
    """The page with a grasp chosen and the dust opened: docs/img/viewer-exploration-page.png
    was taken so (GRASPSCAPE_SCREENSHOTS=docs/img)."""
    import os

    p, console = page
    _open(p, served, "done")
    p.locator("#view3d[data-points]").wait_for()
    p.get_by_test_id("best-A").click()
    p.get_by_test_id("grasp").locator("[data-field=mu_s]").wait_for()
    p.get_by_test_id("dust-toggle").click()
    out = Path(os.environ.get("GRASPSCAPE_SCREENSHOTS") or tmp_path)
    out.mkdir(parents=True, exist_ok=True)
    p.screenshot(path=out / "viewer-exploration-page.png", full_page=True)
    p.evaluate("window.scrollTo(0, 0)")
    p.screenshot(path=out / "viewer-exploration-view.png")  # what the first screen shows
    assert (out / "viewer-exploration-page.png").stat().st_size > 10_000
    assert console.errors == []
