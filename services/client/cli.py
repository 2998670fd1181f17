"""`graspscape submit|status|best|export`: a running coordinator, through the Python client
(`Client`), from any machine that reaches its REST API (--url)."""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

from graspscape.services.local.defaults import DEFAULT_DTHETA_DEG, DEFAULT_LEVELS, DEFAULT_R
from graspscape.shared import cli_args


def _given(value: object, default: object) -> object:
    return default if value is None else value


def _client(args: argparse.Namespace):  # -> Client
    from graspscape.services.client import Client

    return Client(args.url, token=args.token or os.environ.get("GRASPSCAPE_API__TOKEN"))


def _progress_line(state) -> str:  # type: ignore[no-untyped-def]
    p = state.progress
    line = f"exploration {state.id}: {state.status}, {state.poses_done}/{state.poses_total} poses"
    if p is not None and p.eta_s is not None and not state.finished:
        line += f", about {p.eta_s:.0f} s left"
    if state.failures is not None and state.failures.tiles:
        line += f", {state.failures.tiles} tiles failed"
    return line


def _gripper(api, name_or_path: str) -> str:  # type: ignore[no-untyped-def]
    """What the spec names the gripper by: a shipped gripper's name as given; one found on
    this machine (a path, or a name in GRASPSCAPE_GRIPPER_PATH) uploaded, since the
    coordinator elsewhere cannot read it; anything else ('sha256:…') as given."""
    from graspscape.shared.specs.gripper import find_gripper, is_shipped

    found = find_gripper(name_or_path)
    bare = not Path(name_or_path).suffix and len(Path(name_or_path).parts) == 1
    if found is None or (bare and is_shipped(found)):
        return name_or_path
    stored = api.add_gripper(found)
    print(f"gripper {stored.name} uploaded as {stored.gripper}", file=sys.stderr)
    return stored.gripper


def _submit(args: argparse.Namespace) -> int:
    # explore's defaults, so that the same command line asks for the same exploration
    grid = {"dtheta": math.radians(_given(args.dtheta, DEFAULT_DTHETA_DEG)),
            "r_min": _given(args.r_min, DEFAULT_R[0]), "r_max": _given(args.r_max, DEFAULT_R[1]),
            "dr": _given(args.dr, DEFAULT_R[2]), "attitudes": {"rolls": _given(args.rolls, 1)}}
    spec: dict = {"grid": grid, "refinement": {"levels": _given(args.levels, DEFAULT_LEVELS)},
                  "label": args.label or f"graspscape submit {args.object}"}
    # as explore's spec: the preset, with the draws' engines beside it where given
    uncertainty = {"preset": args.uncertainty, "engines": args.draw_engines}
    if any(v is not None for v in uncertainty.values()):
        spec["uncertainty"] = {k: v for k, v in uncertainty.items() if v is not None}
    props = {"mass_kg": args.mass, "friction": args.friction, "scale": args.scale,
             "units": args.units}
    with _client(args) as api:
        is_file = Path(args.object).suffix and Path(args.object).is_file()
        obj = (api.add_object(mesh=args.object, **props) if is_file
               else api.add_object(args.object, **props))
        if args.gripper is not None:
            spec["gripper"] = _gripper(api, args.gripper)
        run = api.submit({**spec, "object_id": obj.id})
        print(run.id)
        print(f"exploration {run.id}: {run.poses_total} poses queued", file=sys.stderr)
        if not args.wait:
            return 0
        final = api.wait(run.id, progress=lambda s: print("\r" + _progress_line(s), end="",
                                                           file=sys.stderr, flush=True))
        print(file=sys.stderr)
        return {"done": 0, "incomplete": 2}.get(final.status, 1)


def _status(args: argparse.Namespace) -> int:
    with _client(args) as api:
        state = api.status(args.exploration_id)
    if args.json:
        print(state.model_dump_json(indent=2))
        return 0
    print(_progress_line(state))
    if state.failures is not None:
        for reason in state.failures.reasons:
            print(f"  {reason.tiles} tiles: {reason.reason or 'no reason recorded'}")
    return 0


def _best(args: argparse.Namespace) -> int:
    with _client(args) as api:
        best = api.best(args.exploration_id, manifold=args.manifold, limit=args.limit,
                        rank=args.rank, engines=args.engines)
    if args.json:
        print(best.model_dump_json(indent=2))
        return 0
    held_in = f", held in {' and '.join(best.engines)}" if best.engines else ""
    print(f"best by {best.rank} (δ {best.delta_deg:.1f}°, {best.delta_mm:.1f} mm{held_in}):")
    for p in best.poses:
        e = p.success
        chance = (f", P(success) {e.k}/{e.n}, 95 % bounds [{e.lower:.2f}, {e.upper:.2f}]"
                  f"{', certified' if e.certified else ''}" if e is not None else "")
        print(f"  pose {p.id}: θ {math.degrees(p.theta):.1f}°, φ {math.degrees(p.phi):.1f}°, "
              f"r {p.r * 1000:.0f} mm, roll {math.degrees(p.roll):.0f}°, μs {p.mu_s:.3f}, "
              f"{p.robust_label or p.outcome}{chance}")
    return 0 if best.poses else 1


def _export(args: argparse.Namespace) -> int:
    with _client(args) as api:
        path = api.export(args.exploration_id, args.what, args.out)
    print(path)
    return 0


# As services/client/http.py's EXPORTS (a test checks they agree), here so that --help
# imports neither httpx nor numpy.
EXPORTS = ("poses.csv", "poses.parquet", "manifolds.json", "graspgen.json", "acronym.h5",
           "object.obj")


def register(subparsers: argparse._SubParsersAction) -> None:
    submit = subparsers.add_parser("submit", help="store an object on a running coordinator "
                                   "and submit its exploration (prints the id)")
    cli_args.add_object(submit)
    cli_args.add_gripper(submit, more="; one found on this machine (not a shipped one) is "
                         "uploaded to the coordinator, which ships it to the workers; "
                         "'sha256:<hash>' names one uploaded before", stored=True)
    cli_args.add_grid(submit, dtheta=DEFAULT_DTHETA_DEG, r=DEFAULT_R, levels=DEFAULT_LEVELS)
    cli_args.add_object_properties(submit)
    submit.add_argument(
        "--uncertainty", choices=["none", "lab", "field"],
        help="the errors P(success) is stated and certified under (default lab, as explore's)")
    cli_args.add_draw_engines(submit)
    submit.add_argument("--label", help="free text shown with the exploration")
    submit.add_argument("--wait", action="store_true",
                        help="wait until it finishes, with progress; exit status as explore's")
    cli_args.add_remote(submit)
    submit.set_defaults(handler=_submit)

    status = subparsers.add_parser("status", help="an exploration's status and progress on a "
                                   "running coordinator")
    cli_args.add_exploration_id(status)
    status.add_argument("--json", action="store_true", help="print the whole answer as JSON")
    cli_args.add_remote(status)
    status.set_defaults(handler=_status)

    best = subparsers.add_parser("best", help="the best grasps of an exploration on a running "
                                 "coordinator")
    cli_args.add_exploration_id(best)
    best.add_argument("--manifold", help="only in this manifold (label A, B, ...)")
    best.add_argument("--limit", type=cli_args.bounded("(poses)", 1, 100, integer=True),
                      default=1, help="how many (default 1)")
    best.add_argument("--rank", help="what ranks them (GET /best's rank; default p_success)")
    best.add_argument("--engines", help="only grasps whose P(success) draws held in each of "
                      "these engines, comma-separated (e.g. pybullet,mujoco)")
    best.add_argument("--json", action="store_true", help="print the answer as JSON")
    cli_args.add_remote(best)
    best.set_defaults(handler=_best)

    export = subparsers.add_parser("export", help="download an export of an exploration from a "
                                   "running coordinator (datasets come with their mesh)")
    cli_args.add_exploration_id(export)
    export.add_argument("--what", choices=EXPORTS, default="poses.csv",
                        help="which export (default poses.csv)")
    export.add_argument("-o", "--out", type=Path, required=True, help="file to write")
    cli_args.add_remote(export)
    export.set_defaults(handler=_export)
