"""The simulation: one pose in, one scored grasp out (see docs/design/simulation.md).

pybullet prints its build time on stderr when first imported, from C; in worker processes
that line lands in the middle of progress bars and logs, so the first import happens here
with the process's stderr pointed at /dev/null (an import error still raises as usual).
"""

from __future__ import annotations

import ctypes
import os
import sys


def _import_pybullet_quietly() -> None:
    if "pybullet" in sys.modules:
        return
    sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no stderr at all: nothing to keep clean
        import pybullet
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        import pybullet  # noqa: F401

        ctypes.CDLL(None).fflush(None)  # in case C stdio buffered the line
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


_import_pybullet_quietly()
