"""Worker-side subcommands: evaluate or picture one pose; `worker` pulls tiles over zenoh."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from graspscape.shared.specs.objects import ObjectSpec


def _pose_args(parser: argparse.ArgumentParser) -> None:
    from graspscape.shared import cli_args

    cli_args.add_object(parser, default="sphere")
    cli_args.add_object_properties(parser)
    cli_args.add_gripper(parser, default="robotiq_3f")
    parser.add_argument("--theta", type=cli_args.degrees(0, 180), required=True, metavar="DEG",
                        help="polar angle of the approach direction from +z, degrees, [0, 180]")
    parser.add_argument("--phi", type=cli_args.degrees(-360, 360), required=True,
                        metavar="DEG", help="azimuth of the approach direction, degrees")
    parser.add_argument("--r", type=cli_args.bounded("m", 0, 0.5), default=0.02, metavar="M",
                        help="start gap palm to object, m (default 0.02)")
    parser.add_argument("--roll", type=cli_args.degrees(-360, 360), default=0.0,
                        metavar="DEG", help="roll about the palm normal, degrees (default 0)")
    parser.add_argument("--settings", type=Path, help="JSON file of SimSettings overrides")
    parser.add_argument("--engine", choices=["pybullet", "mujoco"],
                        help="physics engine (default: the settings', else pybullet)")
    parser.add_argument("--debug", action="store_true", help="show tracebacks")


def _load(args: argparse.Namespace):
    from graspscape.shared.specs.objects import ObjectSpec
    from graspscape.shared.specs.pose import Pose
    from graspscape.shared.specs.sim import SimSettings

    props = {"mass_kg": args.mass, "friction": args.friction, "scale": args.scale,
             "units": args.units}
    props = {k: v for k, v in props.items() if v is not None}
    if Path(args.object).suffix:
        obj = ObjectSpec(mesh_path=args.object, **props)
    else:
        obj = ObjectSpec(name=args.object, **props)
    _validate(obj)
    settings = (SimSettings.model_validate_json(args.settings.read_text())
                if args.settings else SimSettings())
    if args.engine:
        settings = settings.model_copy(update={"engine": args.engine})
    # Degrees on the command line (shared/cli_args.py), radians in the pose.
    pose = Pose(theta=math.radians(args.theta), phi=math.radians(args.phi), r=args.r,
                roll=math.radians(args.roll))
    return obj, settings, pose


def _validate(obj: ObjectSpec) -> None:
    """The one object validation before any physics: warnings to stderr, errors raised."""
    import sys

    from graspscape.workers.sim.objects import inspect_object
    from graspscape.workers.sim.objects.errors import raise_first

    report = inspect_object(obj)
    for message in report.warning_messages():
        print(f"warning: {message}", file=sys.stderr)
    raise_first(report.errors)


def _eval_pose(args: argparse.Namespace) -> int:
    from graspscape.workers.sim.evaluate import evaluate_pose, robustness_pose

    obj, settings, pose = _load(args)
    if args.robustness is not None:
        from graspscape.shared.specs.robustness import TEST_NAMES, RobustnessSettings

        chosen = TEST_NAMES if args.robustness == "all" else tuple(
            name.strip() for name in args.robustness.split(",") if name.strip())
        result = robustness_pose(pose, obj=obj, gripper=args.gripper, settings=settings,
                                 robustness=RobustnessSettings(tests=chosen))
    else:
        result = evaluate_pose(pose, obj=obj, gripper=args.gripper, settings=settings)
    print(json.dumps(result.model_dump(mode="json"), indent=2))
    return 0


def _render_pose(args: argparse.Namespace) -> int:
    from graspscape.workers.sim.evaluate import render_pose

    obj, settings, pose = _load(args)
    path, result = render_pose(pose, args.out, obj=obj, gripper=args.gripper, settings=settings)
    print(f"{result.outcome.value}, μs = {result.mu_s:.3f}; picture of the synthesized grasp: "
          f"{path}")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    ev = subparsers.add_parser("eval-pose", help="simulate one pose and print its result (JSON)")
    _pose_args(ev)
    ev.add_argument("--robustness", nargs="?", const="all", metavar="TESTS",
                    help="also run robustness margins and grasp tests on the synthesized grasp: "
                    "every one (a few seconds), or a comma-separated choice of torque_margin, "
                    "friction_margin, gravity, force, tug, shake (docs/concepts/quality.md)")
    ev.set_defaults(handler=_eval_pose)
    rp = subparsers.add_parser("render-pose", help="write a PNG of the grasp a pose synthesizes")
    _pose_args(rp)
    rp.add_argument("--out", type=Path, default=Path("grasp.png"), help="PNG file to write")
    rp.set_defaults(handler=_render_pose)
    from graspscape.workers.sim.compare_policies import register_compare
    register_compare(subparsers)
    from graspscape.workers.runtime.cli import register_worker
    register_worker(subparsers)
