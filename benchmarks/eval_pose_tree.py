"""One run of bench_eval_pose's 60-pose grid on the graspscape source tree at a path, for
`bench_eval_pose.py --against REV` (issue 21 item 5: exact savings, checked and timed against
the code before them in one run, on the same machine load).

    python benchmarks/eval_pose_tree.py TREE     # prints one JSON line

TREE holds shared/, workers/ and services/ (a checkout, or an extracted `git archive`). The
child imports graspscape from there: a regular package `graspscape` whose parts link to TREE's
folders, put first on sys.path, so it wins over the editable install. The line carries the
grid's results with every field but the timings (to compare for identity), the CPU time of
the grid, the CPU and wall time inside stepSimulation and the steps.
"""

from __future__ import annotations

import atexit
import json
import shutil
import sys
import tempfile
from pathlib import Path


def _import_from(tree: Path) -> None:
    root = Path(tempfile.mkdtemp(prefix="graspscape-tree-"))
    atexit.register(shutil.rmtree, root)  # links only: the tree itself stays
    package = root / "graspscape"
    package.mkdir()
    (package / "__init__.py").write_text("")
    for part in ("shared", "workers", "services"):
        (package / part).symlink_to(tree.resolve() / part, target_is_directory=True)
    sys.path.insert(0, str(root))


def untimed(result: dict) -> dict:
    """A result's fields but its timings (eval_time_s and the phases' seconds; the phases'
    step counts stay): what an exact saving must leave bit for bit as it was."""
    result = dict(result)
    result.pop("eval_time_s", None)
    result["phases"] = {k: v for k, v in result.get("phases", {}).items()
                        if not k.endswith("_s")}
    return result


def main() -> None:
    _import_from(Path(sys.argv[1]))
    import graspscape

    sys.path.insert(1, str(Path(__file__).resolve().parent))
    from bench_eval_pose import pose_grid, run
    from graspscape.shared.specs.objects import ObjectSpec
    from graspscape.shared.specs.sim import SimSettings

    obj = sys.argv[2] if len(sys.argv) > 2 else "pb:mug"
    clock: dict[str, float] = {}
    results, wall = run(ObjectSpec(name=obj), SimSettings(), pose_grid(), clock=clock)
    print(json.dumps({
        "package": str(Path(graspscape.__file__).parent),
        "results": [untimed(json.loads(r.model_dump_json())) for r in results],
        "wall_s": wall, **clock,
    }))


if __name__ == "__main__":
    main()
