"""The viewer in headless Chromium against a real coordinator and a real worker: the list
loads; its progress advances, pushed by server-sent events, while a real exploration of a
built-in runs; clicking a manifold shows its best grasp picture; the submit form starts an
exploration, of a built-in and of a mesh uploaded from the page; the workers page lists the
worker; and no page logs a console error."""

from __future__ import annotations

import hashlib
import re
import signal
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests import object_meshes as meshes
from tests.services.coordinator.web.live import ConsoleLog, LiveStack

pytestmark = pytest.mark.slow

TIMEOUT_MS = 240_000


@pytest.fixture(scope="module")
def stack(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveStack]:
    live = LiveStack(tmp_path_factory.mktemp("viewer"))
    try:
        yield live
    finally:
        live.stop()



@pytest.fixture(scope="module")
def sphere(stack: LiveStack) -> dict[str, Any]:
    """A real sphere exploration, submitted but not waited for (the first test watches it)."""
    eid = stack.explore("sphere", dtheta_deg=60, r=(0.01, 0.02, 0.01), label="browser sphere")
    return {"id": eid}


def _poses_done(page: Any, eid: int) -> tuple[int, int]:
    text = page.get_by_test_id(f"exploration-{eid}").locator("[data-field=poses_done]")
    done, total = re.findall(r"[\d,]+", text.inner_text())
    return int(done.replace(",", "")), int(total.replace(",", ""))


def test_list_loads_and_progress_advances(stack: LiveStack, sphere: dict[str, Any],
                                          page: tuple[Any, ConsoleLog]) -> None:
    p, console = page
    eid = sphere["id"]
    p.goto(stack.base + "/")
    p.get_by_test_id(f"exploration-{eid}").wait_for()
    seen = {_poses_done(p, eid)[0]}
    navigations = []
    p.on("framenavigated", lambda f: navigations.append(f.url))
    deadline = time.monotonic() + TIMEOUT_MS / 1000
    total = _poses_done(p, eid)[1]
    while time.monotonic() < deadline:
        done, total = _poses_done(p, eid)
        seen.add(done)
        if done >= total:
            break
        time.sleep(0.2)
    assert total > 0 and max(seen) == total
    # Pushed in steps while it ran (tiles of 4 poses), without the page reloading.
    assert len(seen) >= 3, seen
    assert not navigations
    row = p.get_by_test_id(f"exploration-{eid}")
    row.locator("[data-field=status]").filter(has_text="done").wait_for()
    assert console.errors == []


def test_best_grasp_picture(stack: LiveStack, sphere: dict[str, Any],
                            page: tuple[Any, ConsoleLog]) -> None:
    p, console = page
    eid = sphere["id"]
    assert stack.wait_finished(eid)["status"] == "done"
    p.goto(f"{stack.base}/#/exploration/{eid}")
    p.locator("img[data-testid=map][data-loaded='1']").wait_for()
    # The r control redraws the cut at one r level (the grid's 10 and 20 mm).
    assert p.locator("#r_mm option").all_inner_texts() == ["every r", "10 mm", "20 mm"]
    p.locator("#r_mm").select_option("20")
    p.locator("img[data-testid=map][data-loaded='1'][src*='r_mm=20']").wait_for()
    p.get_by_test_id("best-A").focus()
    p.keyboard.press("Enter")  # keyboard, not the mouse
    picture = p.locator("img[data-testid=grasp-picture][data-loaded='1']")
    picture.wait_for()
    width = picture.evaluate("img => img.naturalWidth")
    assert width >= 320  # the renderer's picture, decoded
    best = stack.api("GET", f"/explorations/{eid}/best?manifold=A")["poses"][0]
    assert f"/poses/{best['id']}/grasp.png" in picture.get_attribute("src")
    shown = p.get_by_test_id("grasp").locator("[data-field=mu_s]").inner_text()
    assert float(shown) == pytest.approx(best["mu_s"], abs=1e-3)
    assert p.locator("#view3d").get_attribute("data-points") is not None
    assert console.errors == []


def fill_tiny_grid(p: Any) -> None:
    """The submit form set to one start gap on a 90° grid, no refinement or robustness tests:
    an exploration the real worker finishes in seconds."""
    p.locator("#dtheta").fill("90")
    p.locator("#r_min").fill("0.01")
    p.locator("#r_max").fill("0.01")
    p.locator("#levels").select_option("0")
    p.locator("#robustness").select_option("none")


def submit_labelled(p: Any, label: str) -> int:
    """Submits the form under `label` and returns the id of the exploration the page opens."""
    p.locator("#label").fill(label)
    p.get_by_role("button", name="Submit exploration").click()
    p.wait_for_url(re.compile(r"#/exploration/\d+$"))
    return int(p.url.rsplit("/", 1)[1])


def test_submit_from_the_page(stack: LiveStack, page: tuple[Any, ConsoleLog]) -> None:
    p, console = page
    before = stack.api("GET", "/explorations")["total"]
    p.goto(stack.base + "/#/submit")
    p.locator("#object").select_option("cube")
    fill_tiny_grid(p)
    eid = submit_labelled(p, "from the page")
    listed = stack.api("GET", "/explorations")
    assert listed["total"] == before + 1
    row = stack.api("GET", f"/explorations/{eid}")
    assert row["spec"]["label"] == "from the page" and row["status"] in ("queued", "running")
    assert row["spec"]["grid"]["dtheta"] == pytest.approx(3.141592653589793 / 2)
    p.locator("h2").filter(has_text="from the page").wait_for()  # the page shows it
    # It runs on the real worker: the page's numbers follow it to the end.
    p.get_by_test_id("facts").locator("b.status-done").wait_for()
    assert stack.api("GET", f"/explorations/{eid}")["poses_done"] > 0
    assert console.errors == []


def test_upload_a_mesh_from_the_page(stack: LiveStack, page: tuple[Any, ConsoleLog]) -> None:
    """The form's upload path: an OBJ written in millimetres, its mass and units given on the
    page, stored by POST /objects as an upload and explored by the real worker."""
    p, console = page
    mesh = meshes.obj_bytes(meshes.box(60.0))  # a 6 cm cube, in mm
    p.goto(stack.base + "/#/submit")
    p.locator("#object").select_option("__file")
    assert p.locator("#file").is_visible() and not p.locator("#object_name").is_visible()
    p.locator("#file").set_input_files(
        files=[{"name": "page_box.obj", "mimeType": "model/obj", "buffer": mesh}])
    p.locator("#mass").fill("0.15")
    p.locator("#units").select_option("mm")
    fill_tiny_grid(p)
    eid = submit_labelled(p, "uploaded box")
    row = stack.api("GET", f"/explorations/{eid}")
    obj = stack.api("GET", f"/objects/{row['spec']['object_id']}")
    assert (obj["kind"], obj["name"], obj["mesh_format"]) == ("upload", "page_box.obj", "obj")
    assert obj["properties"]["mass_kg"] == pytest.approx(0.15)
    assert obj["properties"]["units"] == "mm"
    assert obj["content_hash"] == hashlib.sha256(mesh).hexdigest()
    p.locator("h2").filter(has_text="uploaded box").wait_for()
    # The uploaded mesh runs on the real worker; the page follows it to the end and shows the
    # mesh the coordinator stored (its 3D view, from the object.obj export).
    p.get_by_test_id("facts").locator("b.status-done").wait_for()
    assert stack.api("GET", f"/explorations/{eid}")["poses_done"] > 0
    p.locator("#view3d[data-points]").wait_for()
    assert console.errors == []


def test_workers_page(stack: LiveStack, page: tuple[Any, ConsoleLog]) -> None:
    p, console = page
    p.goto(stack.base + "/#/workers")
    row = p.get_by_test_id("workers").locator("tr").filter(has_text="web-p0")
    row.wait_for()
    assert "yes" in row.inner_text()  # connected
    assert console.errors == []


def test_screenshots(stack: LiveStack, sphere: dict[str, Any], page: tuple[Any, ConsoleLog],
                     tmp_path: Path) -> None:
    """Every page renders to a picture without a console error (docs/img holds the same
    pictures taken of a mug exploration: tests/services/coordinator/web/screenshots.py)."""
    from tests.services.coordinator.web.screenshots import shoot

    p, console = page
    files = shoot(p, stack.base, sphere["id"], tmp_path)
    assert len(files) == 4 and all(f.stat().st_size > 10_000 for f in files)
    assert console.errors == []


def test_open_event_stream_does_not_hold_up_shutdown(tmp_path: Path) -> None:
    """Uvicorn's graceful exit waits for open responses; an event stream must end on SIGTERM
    (before the fix, one open viewer tab kept the coordinator up for good)."""
    import httpx

    live = LiveStack(tmp_path, procs=0)
    try:
        with httpx.stream("GET", live.base + "/events/explorations", timeout=30) as r:
            assert r.status_code == 200
            next(r.iter_lines())  # the stream is open
            started = time.monotonic()
            live.coordinator.send_signal(signal.SIGTERM)
            live.coordinator.wait(15)
            assert time.monotonic() - started < 10
    finally:
        live.stop()
