"""static/built/atlas3d.js (the atlas's 3D view, built by bundle/build.mjs with esbuild) is built
from the sources as they are now: its header's SHA-256 over its sources is recomputed here, so
editing view3d.js, palette.js, the entry or the vendored three.js without a rebuild fails."""

from __future__ import annotations

import hashlib
import re

from graspscape.services.coordinator.web.router import STATIC_DIR

WEB = STATIC_DIR.parent


def test_atlas_bundle_is_built_from_the_current_sources() -> None:
    text = (STATIC_DIR / "built" / "atlas3d.js").read_text()
    sources = re.search(r"^// sources: (.+)$", text, re.M)
    recorded = re.search(r"^// sources-sha256: ([0-9a-f]{64})$", text, re.M)
    assert sources and recorded, "atlas3d.js has no sources header: rebuild it (build.mjs)"
    paths = sources.group(1).split()
    # The viewer's own 3D code and the vendored three.js are in it, not a copy of either.
    assert {"static/view3d.js", "static/palette.js", "static/vendor/three.module.min.js",
            "bundle/atlas3d.entry.js"} <= set(paths)
    total = hashlib.sha256()
    for path in sorted(paths):
        total.update(f"{path}\n{hashlib.sha256((WEB / path).read_bytes()).hexdigest()}\n"
                     .encode())
    assert total.hexdigest() == recorded.group(1), (
        "static/built/atlas3d.js is older than its sources: "
        "cd services/coordinator/web/bundle && npm ci && npm run build")
    # One classic script: no import or export statement left for a file:// page to refuse.
    body = text.split("\n", 4)[4]
    assert body.startswith("(()=>{") and not re.search(r"^\s*(import|export)\s", body, re.M)
