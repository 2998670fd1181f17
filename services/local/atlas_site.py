"""The atlas's static site: the viewer's pages pre-rendered as HTML that opens from disk
(file://, no server), with each object's exports beside its page.

  index.html              every object: poses, viable share, manifolds, time, its map
  atlas.json              the setting and each object's numbers (what the benchmark reads)
  style.css               the viewer's stylesheet
  atlas3d.js              the viewer's 3D view with three.js as one classic script
  <object>/index.html     the exploration page: numbers, the map cut both ways, the 3D view,
                          the manifold table, the best grasp of each manifold
  <object>/view3d-data.js the 3D view's data: the mesh (OBJ text), the viable approach
                          directions with their manifold labels and, on a table, the
                          resting pose
  <object>/map-*.png, map.svg, manifolds.json, poses.csv, object.obj, graspgen.json,
  grasp-<label>.png

Browsers load no ES module and fetch nothing from file://, so the 3D view is the live
viewer's view3d.js bundled with three.js into one classic script (static/built/atlas3d.js, built by
services/coordinator/web/bundle/build.mjs) and each page's data is a script too.
"""

from __future__ import annotations

import html
import json
import re
import shutil
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from graspscape.services.coordinator.datasets.formats import FORMATS
from graspscape.services.coordinator.manifolds import best as ranking
from graspscape.services.coordinator.manifolds import export
from graspscape.services.coordinator.manifolds import service as manifolds
from graspscape.services.coordinator.manifolds.table import table_document
from graspscape.services.coordinator.maps.picture import picture_bytes
from graspscape.services.coordinator.store.models import ExplorationRow
from graspscape.services.coordinator.web.data import directions
from graspscape.services.coordinator.web.grasp import grasp_png, has_painter
from graspscape.services.coordinator.web.router import STATIC_DIR
from graspscape.services.local.atlas import AtlasEntry, AtlasSetting
from graspscape.shared.specs.support import RestingPose
from sqlalchemy.orm import Session, sessionmaker

_KNOWN = {"label", "name", "description", "digits", "pose_count", "evaluated_count",
          "volume_cm3", "mu_s_min", "mu_s_mean", "mu_s_max", "mu_s_std", "best", "local_maxima"}
MAX_GRASP_PICTURES = 6  # per object: the largest manifolds (a simulation each)
MAX_DIRECTIONS = 20_000  # markers in the 3D view, as the live viewer's default
BUNDLE = "atlas3d.js"


def _e(x: Any) -> str:
    return html.escape(str(x))


def _num(x: Any, digits: int = 3) -> str:
    if x is None:
        return "–"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return f"{x:,}"
    if isinstance(x, float):
        return f"{x:.{digits}f}"
    return _e(x)


def slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "object"


def _page(title: str, body: str, root: str, scripts: str = "") -> str:
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{_e(title)}</title><link rel="icon" href="data:,">
<link rel="stylesheet" href="{root}style.css"></head>
<body><a class="skip" href="#main">Skip to content</a>
<header><h1><a href="{root}index.html">Graspscape atlas</a></h1>
<nav aria-label="Pages"><a href="{root}index.html">Objects</a></nav></header>
<main id="main">{body}</main>
<footer>Pre-rendered by <code>graspscape atlas</code>; the live viewer is
<code>graspscape serve</code> at <code>/</code>. 3D view by three.js 0.170.0 (MIT).
</footer>{scripts}</body></html>
"""


def _table(head: Iterable[str], rows: Iterable[Iterable[str]], numeric: set[int]) -> str:
    th = "".join(f'<th scope="col">{_e(h)}</th>' for h in head)
    body = "".join(
        "<tr>" + "".join(f'<td class="num">{c}</td>' if i in numeric else f"<td>{c}</td>"
                         for i, c in enumerate(row)) + "</tr>" for row in rows)
    return f'<div style="overflow-x:auto"><table><thead><tr>{th}</tr></thead>' \
           f"<tbody>{body}</tbody></table></div>"


def _write_exports(session: Session, eid: int, folder: Path) -> list[str]:
    written = []
    with (folder / "poses.csv").open("wb") as f:
        export.write_poses(session, eid, "csv", f)
    written.append("poses.csv")
    for name in ("object.obj", "graspgen.json"):
        try:
            with (folder / name).open("wb") as f:
                # object.file names the mesh written beside it in the site folder
                FORMATS[name].write(session, eid, f, object_file="object.obj")
            written.append(name)
        except Exception:  # no mesh in this process: the page says what is missing
            (folder / name).unlink(missing_ok=True)
    return written


def write_3d_data(session: Session, eid: int, folder: Path, exports: list[str],
                  resting: RestingPose | None = None) -> None:
    """view3d-data.js: one assignment the bundle reads (a script, as file:// allows no fetch)."""
    mesh = (folder / "object.obj").read_text() if "object.obj" in exports else None
    data = {"obj": mesh,
            "directions": directions(session, eid, MAX_DIRECTIONS).model_dump(mode="json"),
            "resting": None if resting is None else resting.model_dump(mode="json")}
    # JSON is a JS expression; "</" escaped anyway, should the file ever be inlined in HTML.
    text = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    (folder / "view3d-data.js").write_text(f"window.GRASPSCAPE_ATLAS_3D = {text};\n")


_VIEW3D = ('<section class="panel" aria-label="3D view"><h3>Approach directions</h3>'
           '<canvas id="view3d" tabindex="0" aria-label="3D view of the object with the viable '
           'approach directions; arrow keys rotate"></canvas>'
           '<p class="note" id="legend3d">The 3D view needs JavaScript and WebGL.</p>'
           '<div id="picked3d" aria-live="polite"></div></section>')


def _pose_numbers(pose: Any) -> str:
    fields = ["outcome", "mu_s", "effort_max_nm", "torque_margin_nm", "torque_margin_ratio",
              "friction_margin", "mu_g", "mu_f", "mu_m"]
    rows = [f"<dt>θ, φ</dt><dd>{pose.theta * 57.29578:.1f}°, {pose.phi * 57.29578:.1f}°</dd>",
            f"<dt>r</dt><dd>{pose.r:.3f} m</dd>"]
    rows += [f"<dt>{_e(k)}</dt><dd>{_num(getattr(pose, k, None))}</dd>" for k in fields
             if getattr(pose, k, None) is not None]
    return f'<dl class="numbers">{"".join(rows)}</dl>'


def _object_page(session: Session, entry: AtlasEntry, folder: Path, pictures: bool
                 ) -> dict[str, Any]:
    eid = entry.exploration_id
    folder.mkdir(parents=True, exist_ok=True)
    manifolds.ensure_manifolds(session, eid)
    row = session.get(ExplorationRow, eid)
    assert row is not None
    for cut in ("horizontal", "vertical"):
        data, _, _ = picture_bytes(session, eid, "png", cut=cut, title=entry.name)  # type: ignore[arg-type]
        (folder / f"map-{cut}.png").write_bytes(data)
    svg, _, _ = picture_bytes(session, eid, "svg", title=entry.name)
    (folder / "map.svg").write_bytes(svg)
    listed = manifolds.stored_manifolds(session, eid)
    table = table_document(session, eid)  # as GET …/export/manifolds.json
    (folder / "manifolds.json").write_text(json.dumps(table, indent=1))
    exports = _write_exports(session, eid, folder)
    write_3d_data(session, eid, folder, exports, entry.resting)
    dumped = table["manifolds"]
    extra = sorted({k for m in dumped for k, v in m.items()
                    if k not in _KNOWN and not isinstance(v, dict | list)})
    head = ["Manifold", "Description", "Poses", "Volume cm³", *extra, "μs min", "μs mean",
            "μs max", "μs std"]
    rows = [[f"<b>{_e(m['name'])}</b>", _e(m["description"]), _num(m["pose_count"]),
             _num(m["volume_cm3"], 1), *(_num(m.get(k)) for k in extra), _num(m["mu_s_min"]),
             _num(m["mu_s_mean"]), _num(m["mu_s_max"]), _num(m["mu_s_std"])] for m in dumped]
    numeric = {2, 3, *range(4, 4 + len(extra) + 4)}
    grasps = []
    for m in listed[:MAX_GRASP_PICTURES]:
        # Ranked as GET /best ranks by default (P(success), then the robust order).
        best = ranking.best_poses(session, eid, label=m.label, limit=1,
                                  rank=ranking.BEST_DEFAULT_RANK)
        if not best:
            continue
        pose = best[0]
        picture = ""
        if pictures and has_painter():
            name = f"grasp-{m.name}.png"
            (folder / name).write_bytes(grasp_png(session, eid, pose.id))
            picture = (f'<img src="{name}" alt="the best grasp of manifold {_e(m.name)}" '
                       'loading="lazy">')
        grasps.append(f'<section><h3 id="grasp-{_e(m.name)}">Best grasp of {_e(m.name)}</h3>'
                      f'<div class="grasp">{picture}{_pose_numbers(pose)}</div></section>')
    viable = row.viable_count / row.poses_done if row.poses_done else None
    facts = (f'<ul class="facts"><li>status <b class="status-{_e(row.status)}">'
             f"{_e(row.status)}</b></li><li>poses <b>{row.poses_done:,}</b></li>"
             f"<li>viable <b>{'–' if viable is None else f'{100 * viable:.1f} %'}</b></li>"
             f"<li>manifolds <b>{len(listed)}</b></li>"
             f"<li>explored in <b>{entry.wall_s:.0f} s</b></li>{_on_table(entry)}</ul>")
    links = " ".join(f'<a href="{n}">{n}</a>' for n in ["manifolds.json", "map.svg", *exports])
    body = (f"<h2>{_e(entry.name)}</h2>{facts}"
            '<div class="grid"><section class="panel map"><h3>Horizontal cut</h3>'
            f'<img src="map-horizontal.png" alt="behavioral map of {_e(entry.name)}, '
            f'horizontal cut, and a 3D view"></section>{_VIEW3D}'
            '<section class="panel map"><h3>Vertical cut (φ0 = 0°)</h3>'
            f'<img src="map-vertical.png" alt="behavioral map of {_e(entry.name)}, '
            'vertical cut"></section></div>'
            f"<h3>Manifolds</h3>{_table(head, rows, numeric)}{''.join(grasps)}"
            f'<p class="exports">Exports: {links}</p>')
    scripts = f'<script src="view3d-data.js"></script><script src="../{BUNDLE}"></script>'
    (folder / "index.html").write_text(
        _page(f"{entry.name} — Graspscape atlas", body, "../", scripts))
    return {"name": entry.name, "exploration_id": eid, "status": row.status,
            "poses": row.poses_done, "viable_share": viable, "manifolds": len(listed),
            "wall_s": entry.wall_s, "skipped": entry.skipped, "folder": folder.name,
            "eval_time_s_sum": _eval_time(session, eid),
            "resting_index": None if entry.resting is None else entry.resting.index,
            "resting_probability": None if entry.resting is None else entry.resting.probability}


def _on_table(entry: AtlasEntry) -> str:
    if entry.resting is None:
        return ""
    return (f'<li data-field="resting">on a table, resting pose <b>{entry.resting.index}</b> '
            f"(probability <b>{100 * entry.resting.probability:.0f} %</b>)</li>")


def _eval_time(session: Session, eid: int) -> float:
    from graspscape.services.coordinator.store.models import PoseRow
    from sqlalchemy import func, select

    return float(session.scalar(select(func.coalesce(func.sum(PoseRow.eval_time_s), 0.0))
                                .where(PoseRow.exploration_id == eid)) or 0.0)


def write_site(sessions: sessionmaker[Session], entries: list[AtlasEntry], out: Path,
               setting: AtlasSetting, *, pictures: bool = True) -> Path:
    """Write the site under `out` (its pages replaced, other files left); the index path."""
    out.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(STATIC_DIR / "style.css", out / "style.css")
    shutil.copyfile(STATIC_DIR / "built" / BUNDLE, out / BUNDLE)
    summaries = []
    for entry in entries:
        with sessions() as session:
            summaries.append(_object_page(session, entry, out / slug(entry.name), pictures))
    rows = [[f'<a href="{_e(s["folder"])}/index.html">{_e(s["name"])}</a>',
             f'<span class="status-{_e(s["status"])}">{_e(s["status"])}</span>',
             _num(s["poses"]),
             "–" if s["viable_share"] is None else f'{100 * s["viable_share"]:.1f} %',
             _num(s["manifolds"]), f'{s["wall_s"]:.0f}',
             f'<a href="{_e(s["folder"])}/index.html"><img src="{_e(s["folder"])}/'
             f'map-horizontal.png" alt="map of {_e(s["name"])}" width="240" loading="lazy">'
             "</a>"] for s in summaries]
    table = _table(["Object", "Status", "Poses", "Viable", "Manifolds", "Explored in, s",
                    "Map"], rows, {2, 3, 4, 5})
    described = (f"Δθ {setting.dtheta_deg:g}°, r {setting.r_min:g}–{setting.r_max:g} m in "
                 f"steps of {setting.dr:g} m, {setting.rolls} roll(s), {setting.levels} "
                 f"refinement level(s), robustness tests: "
                 f"{', '.join(setting.robustness) or 'none'}"
                 + ("; each object on a table, one map per resting pose"
                    if setting.support == "plane" else ""))
    body = (f"<h2>Atlas: {len(summaries)} objects</h2>"
            f'<p class="note">Setting <b>{_e(setting.name)}</b>: {_e(described)}; gripper '
            "robotiq_3f, policy baseline.</p>" + table)
    (out / "index.html").write_text(_page("Graspscape atlas", body, ""))
    (out / "atlas.json").write_text(json.dumps(
        {"setting": setting.model_dump(mode="json"), "objects": summaries}, indent=1))
    return out / "index.html"
