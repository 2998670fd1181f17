"""G_c versus G_s on every built-in object (issue: haptic policy G_s; paper Table 2).

Runs `compare_object` for each built-in over the "small" pose grid (6 θ × 6 φ × 2 gap cells of
2 cm, roll 0: 72 poses an object and policy, chosen so the whole run takes a few minutes on
one core) and bisects the minimum closing effort of each policy's best-μs pose; then both
policies on 90 poses facing the mug's handle (`mug_handle_sweep`). Reports the
viable-set volumes v_c and v_s (cm³), containment of the G_c-viable poses in the G_s-viable
ones, and the best μs, μg, μf, μm of each policy. The viable set is not yet split into
behavioral manifolds (a later issue), so v is the volume of the whole viable set.

    .venv/bin/python benchmarks/bench_policy_comparison.py   # writes results/policy_comparison.json
    .venv/bin/python benchmarks/bench_policy_comparison.py --grid paper --objects mug
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from graspscape.workers.sim.compare_policies import (
    BUILTIN_OBJECTS,
    GRIDS,
    compare_object,
    markdown_table,
    mug_handle_sweep,
)

try:
    from benchmarks._results import write_results
except ModuleNotFoundError:  # run as a script from the repo root
    from _results import write_results


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--objects", nargs="+", default=list(BUILTIN_OBJECTS))
    parser.add_argument("--grid", choices=sorted(GRIDS), default="small")
    parser.add_argument("--no-min-effort", action="store_true")
    args = parser.parse_args()
    started = time.perf_counter()
    load_start = os.getloadavg()[0]  # the VM is shared: the results say how busy it was
    rows = [compare_object(name, args.grid, min_effort=not args.no_min_effort,
                           log=lambda msg: print(msg, file=sys.stderr, flush=True))
            for name in args.objects]
    figures: dict[str, float] = {}
    for row in rows:
        c, s = row.baseline, row.haptic
        figures[f"{row.object}.v_c_cm3"] = round(c.volume_cm3, 2)
        figures[f"{row.object}.v_s_cm3"] = round(s.volume_cm3, 2)
        if row.contained_share is not None:
            figures[f"{row.object}.contained_share"] = round(row.contained_share, 3)
        for policy, summary in (("c", c), ("s", s)):
            for field in ("best_mu_s", "best_mu_g", "best_mu_f", "best_mu_m",
                          "min_closing_effort"):
                value = getattr(summary, field)
                if value is not None:
                    figures[f"{row.object}.{field}_{policy}"] = round(value, 4)
    gains = [r.volume_gain for r in rows if r.volume_gain is not None]
    if gains:
        figures["mean_volume_gain"] = round(sum(gains) / len(gains), 4)
    figures["objects_with_full_containment"] = sum(r.contained_share == 1.0 for r in rows)
    handle = mug_handle_sweep() if "mug" in args.objects else None
    if handle is not None:
        for key, value in handle.model_dump().items():
            figures[f"mug_handle_sweep.{key}"] = value
    figures["wall_s"] = round(time.perf_counter() - started, 1)
    figures["load_avg_1min_start"] = round(load_start, 2)
    figures["load_avg_1min_end"] = round(os.getloadavg()[0], 2)
    table = markdown_table(rows)
    print(table)
    write_results("policy_comparison", figures, extra={
        "grid": GRIDS[args.grid].model_dump() | {"name": args.grid},
        "table_markdown": table,
        "rows": [r.model_dump(mode="json") for r in rows],
    })


if __name__ == "__main__":
    main()
