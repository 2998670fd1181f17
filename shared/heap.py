"""The garbage collector in the long-running processes: the coordinator's dispatch and the
worker processes.

Both allocate many short-lived objects for every pose (a result batch is thousands of them),
and the cyclic collector runs a full collection every so often, each walking every object
alive: modules, models, schemas, the app, tens of thousands of them. At full load that took a
tenth of the dispatch's time, in pauses that also held every other thread. What exists once a
process is set up lives as long as the process, so it is moved out of the collector's sight.
"""

from __future__ import annotations

import functools
import gc


@functools.cache
def freeze_startup_heap() -> None:
    """Once per process, when it is set up: collect, then freeze what is left (gc.freeze),
    so that later collections walk only what was allocated since."""
    gc.collect()
    gc.freeze()
