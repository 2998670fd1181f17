"""One real worker process (the worker loop of `graspscape worker`, instant evaluations) whose
evaluation of the given poses returns a NaN effort, as a blown-up simulation does. With
`--unchecked` the loop's finite check is taken out, as in a worker of before it: the NaN
goes out in the batch (as `null`) and only the coordinator can stop the loop.

    python -m tests.faults.nan_worker ENDPOINT NAME CACHE_DIR POSE_S EXPLORATION:KEY ...
        [--unchecked]
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

from graspscape.workers.runtime import process
from graspscape.workers.runtime.config import WorkerConfig
from graspscape.workers.runtime.process import WorkerProcess


class BlownUp(WorkerProcess):
    poisoned: frozenset[str] = frozenset()

    def _evaluate(self, tile, obj, pose, donors=None):  # type: ignore[no-untyped-def]
        result = super()._evaluate(tile, obj, pose, donors)
        if f"{tile.exploration_id}:{pose.key()}" not in self.poisoned:
            return result
        logging.getLogger("graspscape.worker").warning("pose %s: NaN injected", pose.key())
        return result.model_copy(update={"effort_max_nm": float("nan")})  # no validation


def main(argv: list[str]) -> None:
    unchecked = "--unchecked" in argv
    endpoint, name, cache_dir, pose_s, *poisoned = [a for a in argv if a != "--unchecked"]
    logging.basicConfig(level=logging.INFO,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    if unchecked:
        process.finite_or_error = lambda result: result  # type: ignore[assignment]
    BlownUp.poisoned = frozenset(poisoned)
    config = WorkerConfig(connect=[endpoint], name=name, procs=1, cache_dir=Path(cache_dir),
                          instant=True, instant_pose_s=float(pose_s), backoff_max_s=1.0)
    BlownUp(config, 0).run()


if __name__ == "__main__":
    main(sys.argv[1:])
