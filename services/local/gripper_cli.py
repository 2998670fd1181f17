"""`graspscape gripper check PATH|NAME`: load a gripper (a TOML of boxes, or a URDF or MJCF
gripper's folder), render it open and closed, close it on a sphere and a box, and print what it
inferred and what looks wrong (workers/sim/gripper/check.py; with --engine mujoco
workers/sim/mj/check.py; docs/howto/add-gripper.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

from graspscape.shared.specs.sim import ENGINE_NAMES


def _check(args: argparse.Namespace) -> int:
    from graspscape.shared.specs.gripper import MjcfGripperSpec, load_gripper
    from graspscape.workers.sim.evaluate import default_cache_dir
    from graspscape.workers.sim.gripper.check import check_gripper

    spec = load_gripper(str(args.gripper))
    out = args.out or Path(f"gripper-check-{spec.name}")
    engine = args.engine or ("mujoco" if isinstance(spec, MjcfGripperSpec) else "pybullet")
    if engine == "mujoco":
        from graspscape.workers.sim.mj.check import check_gripper_mujoco

        report = check_gripper_mujoco(spec, default_cache_dir())
    else:
        report = check_gripper(spec, default_cache_dir(), out)
    if args.json:
        print(report.model_dump_json(indent=2))
        return 1 if report.problems else 0
    vendor = report.vendor_names
    print(f"{report.gripper} ({report.kind}): mass {report.mass_kg:.3f} kg, reach "
          f"{report.reach_m * 1000:.0f} mm past the palm (declared "
          f"{report.declared_reach_m * 1000:.0f}), opening {report.opening_m * 1000:.0f} mm, "
          f"closed in free air {report.closed_gap_m * 1000:.0f} mm")
    for digit, links in report.digits.items():
        named = ", ".join(f"{link} ({vendor[link]})" if link in vendor and vendor[link] != link
                          else link for link in links)
        print(f"  digit {digit}: {len(links)} link(s): {named}")
    for j in report.joints:
        print(f"  joint {j.joint} ({j.vendor}): open {j.open:+.3f} → closed {j.closed:+.3f}"
              f"{'' if j.moved else '  (did not move)'}")
    for t in report.trials:
        print(f"  {t.object}, {t.start}: {t.outcome}, μs {t.mu_s:.2f}, touching "
              f"{', '.join(t.links_in_contact) or 'nothing'}")
    if report.pictures:
        print(f"  pictures in {out}/")
    for warning in report.warnings:
        print(f"  warning: {warning}")
    for problem in report.problems:
        print(f"  problem: {problem}")
    if not report.problems:
        print("  no problems found")
    return 1 if report.problems else 0


def register(subparsers: argparse._SubParsersAction) -> None:
    gripper = subparsers.add_parser("gripper", help="gripper descriptions: check one")
    commands = gripper.add_subparsers(dest="gripper_command", required=True, metavar="ACTION")
    check = commands.add_parser(
        "check", help="load a gripper, render it, close it on a sphere and a box, report")
    check.add_argument("gripper", help="a gripper name (searched in GRASPSCAPE_GRIPPER_PATH, "
                       "then the shipped grippers), a TOML spec, or a URDF or MJCF gripper's "
                       "folder (with gripper.toml; not the .urdf or .xml file itself)")
    check.add_argument("-o", "--out", type=Path, help="folder of the pictures "
                       "(default gripper-check-NAME)")
    check.add_argument("--json", action="store_true", help="print the report as JSON")
    check.add_argument("--engine", choices=ENGINE_NAMES, help="the physics engine to check it "
                       "in (default: mujoco for an MJCF gripper, which only MuJoCo loads, else "
                       "pybullet); the MuJoCo check draws no pictures")
    check.set_defaults(handler=_check)
