"""The static atlas site in headless Chromium, opened from disk (file://, no server): the
object page's 3D view draws the object's mesh and its viable approach directions in the
manifolds' colours, turns with the keyboard, shows a marker's numbers on a click, draws the
table under an object at rest on one, and no page logs a console error (a script that did not
load is one)."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import pytest
from graspscape.services.local.atlas import SETTINGS, AtlasEntry
from graspscape.services.local.atlas_site import write_site
from graspscape.services.local.compose import open_store, wire
from graspscape.shared.specs.support import RestingPose

from tests.services.coordinator.web.live import ConsoleLog
from tests.services.local.test_atlas_site import oracle_sphere, read_data

pytestmark = pytest.mark.slow

TAB10 = [(0x1F, 0x77, 0xB4), (0xFF, 0x7F, 0x0E), (0x2C, 0xA0, 0x2C), (0xD6, 0x27, 0x28)]


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A one-object site: a sphere explored with the oracle, its mesh exported as the atlas
    does (the workers' object preparation wired in), no grasp pictures."""
    folder = tmp_path_factory.mktemp("atlas")
    wire()
    engine, sessions = open_store(f"sqlite:///{folder / 'atlas.db'}")
    try:
        eid = oracle_sphere(sessions, dtheta_deg=30)
        entry = AtlasEntry(name="sphere", exploration_id=eid, skipped=False, wall_s=1.0)
        return write_site(sessions, [entry], folder / "site", SETTINGS["reduced"],
                          pictures=False)
    finally:
        engine.dispose()



def _pixels(png: bytes) -> Any:
    import numpy as np
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)


def _near(img: Any, rgb: tuple[int, int, int], tol: int = 8) -> Any:
    import numpy as np

    return np.all(np.abs(img - np.array(rgb)) <= tol, axis=-1)


def test_object_page_3d_view_from_disk(site: Path, page: tuple[Any, ConsoleLog]) -> None:
    import numpy as np

    p, console = page
    data = read_data(site.parent / "sphere" / "view3d-data.js")
    assert data["obj"], "the sphere's mesh was exported beside the page"
    p.goto(site.as_uri())  # the index, from disk
    p.get_by_role("link", name="sphere").first.click()
    assert p.url.startswith("file://") and p.url.endswith("/sphere/index.html")
    canvas = p.locator("#view3d[data-ready='1']")
    canvas.wait_for()
    n = len(data["directions"]["pose_id"])
    assert canvas.get_attribute("data-points") == str(n)
    assert p.locator("#legend3d").inner_text().startswith(f"{n} of {n} viable poses shown")
    shot = _pixels(canvas.screenshot())
    # Drawn, not blank: the grey shaded mesh and markers in the colours of manifolds A and B
    # (the oracle's two grasp types), as on the map pictures.
    labels = sorted(set(data["directions"]["label"]))
    assert labels == [0, 1]
    for label in labels:
        assert _near(shot, TAB10[label]).sum() > 30, f"no marker of manifold {label}"
    grey = (np.abs(shot[..., 0] - shot[..., 1]) < 6) & (np.abs(shot[..., 1] - shot[..., 2]) < 6)
    mesh = grey & (shot[..., 0] < 200) & (shot[..., 0] > 40)
    assert mesh.sum() > 2000, "no shaded mesh"
    # Keyboard: an arrow key turns the view.
    canvas.focus()
    p.keyboard.press("ArrowLeft")
    p.keyboard.press("ArrowLeft")
    turned = _pixels(canvas.screenshot())
    assert (np.abs(turned - shot).sum(axis=-1) > 30).sum() > 500
    # A click on a marker shows that pose's numbers.
    ys, xs = np.nonzero(_near(turned, TAB10[0]))
    box = canvas.bounding_box()
    picked = p.locator("#picked3d dl.numbers")
    for i in np.linspace(0, len(xs) - 1, 8).astype(int):
        canvas.click(position={"x": float(xs[i]) * box["width"] / turned.shape[1],
                               "y": float(ys[i]) * box["height"] / turned.shape[0]})
        if picked.count():
            break
    assert picked.count() == 1, "no marker picked"
    pose = int(p.locator("#picked3d [data-field=pose]").inner_text())
    assert pose in data["directions"]["pose_id"]
    assert p.locator("#picked3d [data-field=manifold]").inner_text() in ("A", "B")
    assert console.errors == []


def test_site_pages_load_every_file_from_disk(site: Path, page: tuple[Any, ConsoleLog]) -> None:
    """Index and object page: every request is a file:// one and none fails."""
    p, console = page
    failed: list[str] = []
    urls: list[str] = []
    p.on("requestfailed", lambda r: failed.append(r.url))
    p.on("request", lambda r: urls.append(r.url))
    for path in (site, site.parent / "sphere" / "index.html"):
        p.goto(path.as_uri())
        p.wait_for_load_state("load")
    p.locator("#view3d[data-ready='1']").wait_for()
    assert failed == [] and console.errors == []
    assert any(u.endswith("/atlas3d.js") for u in urls)
    assert all(u.startswith(("file://", "data:")) for u in urls), urls


def test_object_on_a_table_draws_the_table(tmp_path: Path, page: tuple[Any, ConsoleLog]) -> None:
    p, console = page
    wire()
    engine, sessions = open_store(f"sqlite:///{tmp_path / 'atlas.db'}")
    try:
        eid = oracle_sphere(sessions, dtheta_deg=90)
        # The sphere (4 cm radius) at rest: its centre 4 cm above the table, turned a quarter.
        resting = RestingPose(index=0, probability=1.0, position=(0.0, 0.0, 0.04),
                              quaternion=(0.0, 0.7071068, 0.0, 0.7071068))
        entries = [AtlasEntry(name="sphere rest0", exploration_id=eid, skipped=False,
                              wall_s=1.0, resting=resting),
                   AtlasEntry(name="sphere", exploration_id=eid, skipped=False, wall_s=1.0)]
        index = write_site(sessions, entries, tmp_path / "site", SETTINGS["reduced"],
                           pictures=False)
    finally:
        engine.dispose()
    p.goto((index.parent / "sphere_rest0" / "index.html").as_uri())
    canvas = p.locator("#view3d[data-ready='1']")
    canvas.wait_for()
    assert canvas.get_attribute("data-table") == "0.0400"
    assert "resting pose 0" in p.locator("[data-field=resting]").inner_text()
    p.goto((index.parent / "sphere" / "index.html").as_uri())
    p.locator("#view3d[data-ready='1']").wait_for()
    assert p.locator("#view3d").get_attribute("data-table") is None
    assert console.errors == []
