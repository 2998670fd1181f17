"""Screenshots of every viewer page: `python -m tests.services.coordinator.web.screenshots
BASE_URL EXPLORATION_ID OUT_DIR` (docs/img/viewer-*.png were taken so, of a mug exploration),
and of an atlas object page opened from disk: `python -m tests.services.coordinator.web.
screenshots --atlas SITE_DIR OBJECT_FOLDER OUT_DIR` (docs/img/viewer-atlas.png, of the mug)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

PAGES = {"viewer-list.png": "#/", "viewer-exploration.png": "#/exploration/{id}",
         "viewer-submit.png": "#/submit", "viewer-workers.png": "#/workers"}


def shoot(page: Any, base: str, exploration_id: int, out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for name, hash_ in PAGES.items():
        page.goto(f"{base}/{hash_.format(id=exploration_id)}")
        page.wait_for_load_state("networkidle")
        if "exploration/" in hash_:
            page.locator("img[data-testid=map][data-loaded='1']").wait_for()
            page.locator("#view3d[data-points]").wait_for()
            page.locator("[data-testid^=best-]").first.click()
            page.locator("img[data-testid=grasp-picture][data-loaded='1']").wait_for()
        page.screenshot(path=out / name, full_page=True)
        files.append(out / name)
    return files


def shoot_atlas(page: Any, site: Path, folder: str, out: Path) -> Path:
    """The object page of an atlas site, from file://, its 3D view drawn."""
    out.mkdir(parents=True, exist_ok=True)
    page.goto((site / folder / "index.html").resolve().as_uri())
    page.wait_for_load_state("load")
    page.locator("#view3d[data-ready='1']").wait_for()
    # The grasp pictures load lazily, on scrolling: a full-page picture wants them all.
    page.evaluate("""() => Promise.all([...document.images].map((img) => {
        img.loading = "eager";
        return img.complete ? null : new Promise((done) => { img.onload = img.onerror = done; });
    }))""")
    page.screenshot(path=out / "viewer-atlas.png", full_page=True)
    return out / "viewer-atlas.png"


def main() -> int:
    from playwright.sync_api import sync_playwright

    from tests.services.coordinator.web.live import CHROMIUM_ARGS, chromium_executable

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium_executable(), args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        page.set_default_timeout(120_000)
        if sys.argv[1] == "--atlas":
            print(shoot_atlas(page, Path(sys.argv[2]), sys.argv[3], Path(sys.argv[4])))
        else:
            base, exploration_id, out = sys.argv[1], int(sys.argv[2]), Path(sys.argv[3])
            for f in shoot(page, base, exploration_id, out):
                print(f)
        browser.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
