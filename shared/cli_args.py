"""The `graspscape` command's one vocabulary: each argument that several subcommands take is
added here, once, so that it has the same flag, unit, help and validation everywhere
(docs/reference/cli-vocabulary.md, "Vocabulary"; tests/services/local/test_cli_vocabulary.py walks
every parser).

Angles are degrees on the command line and lengths metres unless the flag names its unit
(`--r-mm`); a value out of range is refused by argparse as one line naming the flag, the
value, the range and the unit. Subcommands that add options of their own add them beside
these calls, so that new flags merge without touching the shared ones.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path

from graspscape.shared.specs.numbers import UNDERFLOW_MESSAGE, underflows

OBJECT_HELP = ("built-in name (sphere, cube, mug, ...), pb:<name>, ycb:<Folder> or a mesh "
               "file")
GRIPPER_HELP = ("gripper: a name (robotiq_3f, ...; searched in GRASPSCAPE_GRIPPER_PATH, then "
                "the shipped grippers), a TOML spec file, or a URDF gripper's folder (with "
                "gripper.toml)")
DEFAULT_URL = "http://127.0.0.1:8000"


def bounded(unit: str, low: float | None = None, high: float | None = None, *,
            low_open: bool = False, integer: bool = False) -> Callable[[str], float]:
    """An argparse type: a finite number within [low, high] (low excluded when `low_open`),
    refused as "VALUE is not in RANGE UNIT"; argparse prefixes the flag."""

    def parse(text: str) -> float:
        try:
            value: float = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{text!r} is not {'an integer' if integer else 'a number'} ({unit})") from None
        if underflows(text):
            raise argparse.ArgumentTypeError(f"{text!r}: {UNDERFLOW_MESSAGE} ({unit})")
        below = low is not None and (value <= low if low_open else value < low)
        above = high is not None and value > high
        if not math.isfinite(value) or below or above:
            left = "(" if low_open else "["
            lo = "-inf" if low is None else f"{low:g}"
            hi = "inf" if high is None else f"{high:g}"
            raise argparse.ArgumentTypeError(f"{text} is not in {left}{lo}, {hi}] {unit}")
        return value

    parse.__name__ = unit  # argparse names the type in its "invalid ..." messages
    return parse


def degrees(low: float, high: float, *, low_open: bool = False) -> Callable[[str], float]:
    return bounded("degrees", low, high, low_open=low_open)


def add_object(parser: argparse.ArgumentParser, *, default: str | None = None) -> None:
    """The object, as a positional (where `default` is given, it may be left out); the
    earlier `--object` spelling stays accepted (`resolve_object` merges them)."""
    text = OBJECT_HELP if default is None else f"{OBJECT_HELP} (default {default})"
    parser.add_argument("object", nargs="?", help=text)
    add_hidden_alias(parser, "--object", "object_flag")
    parser.set_defaults(object_required=default is None, object_default=default)


def add_object_properties(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--mass", type=bounded("kg", 0, 50, low_open=True),
                        help="object mass, kg (default: from the object)")
    parser.add_argument("--friction", type=bounded("(friction coefficient)", 0, 5),
                        help="object friction coefficient (default: from the object)")
    parser.add_argument("--scale", type=bounded("(scale factor)", 0, 100, low_open=True),
                        help="uniform object scale (default 1)")
    parser.add_argument("--units", choices=["m", "cm", "mm"],
                        help="length unit of a mesh file (default m)")


def gripper(text: str) -> str:
    """An argparse type: a gripper name as given, a path made absolute (the workers may run
    elsewhere in the file system: another folder, another process); refused when it names
    none, saying what to pass instead."""
    from graspscape.shared.specs.gripper import find_gripper, unknown_gripper_message

    found = find_gripper(text)
    if found is None:
        raise argparse.ArgumentTypeError(unknown_gripper_message(text))
    is_name = not Path(text).suffix and len(Path(text).parts) == 1 and not Path(text).exists()
    return text if is_name else str(Path(text).expanduser().resolve())


def stored_or_gripper(text: str) -> str:
    """`gripper`, or the name of one stored on a coordinator ('sha256:<hash>', POST
    /grippers), for the commands that talk to one."""
    from graspscape.shared.specs.gripper import STORED_GRIPPER

    return text if STORED_GRIPPER.match(text) else gripper(text)


def add_gripper(parser: argparse.ArgumentParser, default: str | None = None,
                more: str = "", *, stored: bool = False) -> None:
    parser.add_argument("--gripper", type=stored_or_gripper if stored else gripper,
                        default=default, metavar="NAME|PATH",
                        help=f"{GRIPPER_HELP}{more} (default robotiq_3f)")


def add_grid(parser: argparse.ArgumentParser, *, dtheta: float, r: tuple[float, float, float],
             levels: int) -> None:
    """The pose grid: approach-direction step (degrees), start gaps (m), rolls, refinement.
    Defaults are given as None so a command can tell what was asked for; `dtheta`, `r` and
    `levels` are the defaults the help states."""
    parser.add_argument("--dtheta", type=degrees(0.5, 90, low_open=True), metavar="DEG",
                        help=f"angle between approach directions, degrees, (0.5, 90] "
                        f"(default {dtheta:g})")
    length = bounded("m", 0, 1)
    parser.add_argument("--r-min", type=length, metavar="M",
                        help=f"smallest start gap palm to object, m (default {r[0]:g})")
    parser.add_argument("--r-max", type=length, metavar="M",
                        help=f"largest start gap, m (default {r[1]:g})")
    parser.add_argument("--dr", type=bounded("m", 0, 1, low_open=True), metavar="M",
                        help=f"start gap step, m (default {r[2]:g})")
    parser.add_argument("--rolls", type=int, choices=[1, 2, 4, 8],
                        help="rolls about the palm normal per approach point (default 1)")
    parser.add_argument("--levels", type=int, choices=range(7), metavar="{0..6}",
                        help=f"border refinement levels: halvings of the grid where "
                        f"neighbouring poses differ (default {levels})")


def add_support(parser: argparse.ArgumentParser) -> None:
    """What the object rests on (docs/concepts/support.md): nothing, or a table."""
    parser.add_argument("--support", choices=["none", "plane"],
                        help="none: the free-floating object (default); plane: the object at "
                        "rest on a table, one exploration per stable resting pose (at least "
                        "5 %% likely, at most 4)")
    parser.add_argument("--support-friction", type=bounded("(friction coefficient)", 0, 3,
                                                           low_open=True),
                        metavar="MU", help="object–table friction coefficient (default 0.5)")


ENGINES = ("pybullet", "mujoco")  # shared/specs/sim.py's EngineName, without importing it


def engine_list(text: str) -> tuple[str, ...]:
    """An argparse type: comma-separated physics engines, each known and named once."""
    names = tuple(e.strip() for e in text.split(",") if e.strip())
    unknown = [e for e in names if e not in ENGINES]
    if not names or unknown or len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a list of distinct engines ({', '.join(ENGINES)})")
    return names


def add_draw_engines(parser: argparse.ArgumentParser) -> None:
    """The engines each P(success) draw is simulated in (the spec's uncertainty engines)."""
    parser.add_argument(
        "--draw-engines", type=engine_list, metavar="ENGINES",
        help="physics engines each P(success) draw is simulated in, comma-separated "
        "(default: the exploration's engine); pybullet,mujoco: a draw succeeds only where it "
        "holds in both")


def add_procs(parser: argparse.ArgumentParser, help_text: str = "worker processes "
              "(default: cores)", *, low: int = 1) -> None:
    parser.add_argument("--procs", type=bounded("processes", low, 4096, integer=True),
                        help=help_text)


def add_store(parser: argparse.ArgumentParser, *,
              data_dir_default: str = "the settings' data_dir, else data",
              url: bool = True) -> None:
    """Where the coordinator's database is: --data-dir (the embedded SQLite file in it) and,
    where a command can read another database, --database-url."""
    parser.add_argument("--data-dir", type=Path,
                        help=f"folder of the embedded SQLite database (coordinator.db) and "
                        f"results (default: {data_dir_default})")
    if url:
        parser.add_argument("--database-url", help="SQLAlchemy URL of the coordinator's "
                            "database, e.g. postgresql+psycopg://host/db (default: settings; "
                            "overrides --data-dir)")


def add_remote(parser: argparse.ArgumentParser) -> None:
    """A running coordinator's REST API (the Python client's commands)."""
    parser.add_argument("--url", default=DEFAULT_URL,
                        help=f"the coordinator's base URL (default {DEFAULT_URL})")
    parser.add_argument("--token", help="API token of its mutating routes, where set "
                        "(default: GRASPSCAPE_API__TOKEN)")


def add_exploration_id(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("exploration_id", type=bounded("(exploration id)", 1, 2**31 - 1,
                                                       integer=True),
                        help="the exploration's id (as explore, submit and serve print it)")


def add_hidden_alias(parser: argparse.ArgumentParser, flag: str, dest: str,
                     **kwargs: object) -> None:
    """An earlier spelling of a flag, still accepted and not shown
    (docs/reference/cli-vocabulary.md, "Other spellings")."""
    parser.add_argument(flag, dest=dest, help=argparse.SUPPRESS, **kwargs)  # type: ignore[arg-type]


def resolve_object(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """After parsing: the object from the positional or the earlier `--object` spelling, else
    the command's default; argparse's one-line error where a command needs one and got none."""
    if not hasattr(args, "object_required"):
        return
    flag = getattr(args, "object_flag", None)
    if flag is not None and args.object is not None and args.object != flag:
        parser.error(f"the object given twice: {args.object} and --object {flag}")
    args.object = args.object or flag or args.object_default
    if args.object is None:
        parser.error(f"the following arguments are required: object ({OBJECT_HELP})")
