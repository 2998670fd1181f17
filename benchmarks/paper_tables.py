"""The paper's three tables, our numbers (issue 20): results/paper_tables*.json,
docs/design/paper.md.

Table 1 (per object): the best held grasp by each of μs, μg, μf, μm and the torque margin
ratio over the poses of the object's Table 3 runs, then its minimum closing effort by
bisection (paper_tables_t12.py). Table 2 (per object): G_c against G_s on one pose grid:
v_c, v_s, containment share, best μ (paper_tables_t12.py).

Table 3 (per object): the adaptive exploration at 1, 2, 4 and 8 rolls first, then PPO (≥ 3
seeds: mean and spread), CMA-ES and random search, each with exactly as many evaluations as
adaptive spent at each roll count (paper_tables_t3.py: matched in evaluations, not wall
time); all through the same scheduler, store and 2 worker processes (services/local/run
.run_local with a pool of 2), counted by the one budget accounting
(exploration/accounting.py): best μs ("quality"), grasps (viable poses), misses, and time; as
fractions of PPO's mean like the paper (at matched evaluations, and in the paper's layout
against the PPO with the largest budget), and absolute.

Time. The machine is shared (the load is recorded, per object too), so time is not read off
the run's clock alone: an evaluation's time is its eval_time_s as the worker measured it (its
wall clock: a loaded machine inflates it, for every explorer alike), and a run's time is the
sum over the poses it evaluated / 2 workers + the coordinator's measured store and decision
time. The poses of one object are simulated once and reused by every run that asks for them
(an evaluation is a pure function of pose, object, gripper and settings), at the eval_time_s
of their first simulation. Time to the first grasp: the same sum, in the order the poses were
stored, up to the first viable one.

Objects. `--objects` names them; `all` is every YCB object beside the checkout, cheapest to
simulate first (paper_tables_sizes.YCB_BY_COST), so that a run stopped by the clock has done
as many objects as it could; the results file is rewritten after each object (`complete`
says whether all ran). `--tables 3` runs Table 3 alone (Table 1 needs Table 3's poses).

    .venv/bin/python benchmarks/paper_tables.py                       # the default subset
    .venv/bin/python benchmarks/paper_tables.py --objects all --tables 3 \\
        --name paper_tables_matched                                   # docs/design/paper.md's run
    .venv/bin/python benchmarks/paper_tables.py --size full --objects all --processes 16
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

try:
    from benchmarks._results import write_results
    from benchmarks.paper_tables_docs import markdown
    from benchmarks.paper_tables_sizes import (
        DEFAULT_YCB,
        SIZES,
        Size,
        all_ycb,
        cheapest_first,
    )
    from benchmarks.paper_tables_t3 import summarise_table3, table3_object
    from benchmarks.paper_tables_t12 import TABLE1_METRICS, init_worker, table1_object, table2
except ModuleNotFoundError:  # run as a script: benchmarks/ itself is on sys.path
    from _results import write_results
    from paper_tables_docs import markdown
    from paper_tables_sizes import DEFAULT_YCB, SIZES, Size, all_ycb, cheapest_first
    from paper_tables_t3 import summarise_table3, table3_object
    from paper_tables_t12 import TABLE1_METRICS, init_worker, table1_object, table2

__all__ = ["SIZES", "run", "summarise"]


def summarise(rows: dict[str, Any], size: Size) -> dict[str, Any]:
    """The figures of the rows so far; sets rows["table3_fractions"]."""
    figures: dict[str, Any] = {}
    for row in rows["table2"]:
        short = row["object"].removeprefix("ycb:")
        figures[f"t2.{short}.v_c_cm3"] = round(row["baseline"]["volume_cm3"], 2)
        figures[f"t2.{short}.v_s_cm3"] = round(row["haptic"]["volume_cm3"], 2)
        figures[f"t2.{short}.contained_share"] = row["contained_share"]
        figures[f"t2.{short}.best_mu_s_c"] = row["baseline"]["best_mu_s"]
        figures[f"t2.{short}.best_mu_s_s"] = row["haptic"]["best_mu_s"]
    for name, t1 in rows["table1"].items():
        short = name.removeprefix("ycb:")
        for metric in TABLE1_METRICS:
            if metric in t1:
                figures[f"t1.{short}.by_{metric}.min_closing_effort_nm"] = \
                    t1[metric]["min_closing_effort_nm"]
    if rows["table3"]:
        rows["table3_fractions"], t3 = summarise_table3(rows["table3"], size.rolls)
        figures.update(t3)
    return figures


def run(objects: Sequence[str], size: Size, processes: int = 2,
        checkpoint: Callable[[dict[str, Any], bool], None] | None = None,
        tables: Sequence[int] = (1, 2, 3)) -> dict[str, Any]:
    """The tables asked for: Table 2 on `size.simple` + `objects` first, then Tables 3 and 1
    object by object; returns figures and rows. `checkpoint(out, complete)` gets the results
    so far after each stage (the benchmark writes them, so that a run cut short still leaves
    the stages it finished)."""
    if 1 in tables and 3 not in tables:
        raise ValueError("Table 1 chooses its grasps among Table 3's poses: add table 3")
    started = time.perf_counter()
    rows: dict[str, Any] = {"table1": {}, "table2": [], "table3": {}}

    def out() -> dict[str, Any]:
        figures = summarise(rows, size)
        figures["objects_done"] = len(rows["table3"])
        figures["wall_s"] = round(time.perf_counter() - started, 1)
        figures["load_avg_1min_now"] = round(os.getloadavg()[0], 2)
        return {"figures": figures, "rows": rows}

    with ProcessPoolExecutor(processes, initializer=init_worker,
                             initargs=([size.table2_grid],)) as pool:
        if 2 in tables:
            rows["table2"] = table2([*size.simple, *objects], size.table2_grid, pool)
            if checkpoint:
                checkpoint(out(), False)
        if 3 in tables:
            for name in objects:
                row, every, settings = table3_object(name, size, pool, processes)
                rows["table3"][name] = row
                if 1 in tables:
                    rows["table1"][name] = table1_object(name, every, settings,
                                                         size.effort_tolerance_nm, pool)
                if checkpoint and name != objects[-1]:
                    checkpoint(out(), False)
    final = out()
    if checkpoint:
        checkpoint(final, True)
    return final


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", choices=sorted(SIZES), default="small")
    parser.add_argument("--objects", nargs="+", default=list(DEFAULT_YCB),
                        help="objects of Tables 1 and 3 (also in Table 2); 'all': every YCB "
                        "object beside the checkout, cheapest first")
    parser.add_argument("--tables", type=int, nargs="+", choices=(1, 2, 3), default=[1, 2, 3],
                        help="which tables to compute (Table 1 needs 3)")
    parser.add_argument("--processes", type=int, default=2, help="worker processes")
    parser.add_argument("--name", default="paper_tables", help="results file name")
    parser.add_argument("--render", metavar="RESULTS_JSON",
                        help="print the docs' markdown tables of a results file; run nothing")
    args = parser.parse_args()
    if args.render:
        print(markdown(json.loads(Path(args.render).read_text())["rows"]))
        return
    objects = list(cheapest_first(all_ycb())) if args.objects == ["all"] else args.objects
    size = SIZES[args.size]
    load_before = round(os.getloadavg()[0], 2)

    def write(out: dict[str, Any], complete: bool) -> None:
        out["figures"]["load_avg_1min_at_start"] = load_before
        out["figures"]["complete"] = complete
        if complete:
            print(markdown(out["rows"]))
        write_results(args.name, out["figures"], extra={
            "size": args.size, "objects": objects, "tables": args.tables,
            "sizes": {args.size: repr(size)}, "rows": out["rows"],
        })

    run(objects, size, args.processes, checkpoint=write, tables=args.tables)


if __name__ == "__main__":
    main()
