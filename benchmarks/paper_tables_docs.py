"""The docs' markdown of a paper-tables results file, beside the paper's figures
(benchmarks/paper_tables.py --render RESULTS_JSON)."""

from __future__ import annotations

from typing import Any

try:
    from benchmarks.paper_tables_t12 import TABLE1_METRICS
except ModuleNotFoundError:  # run as a script: benchmarks/ itself is on sys.path
    from paper_tables_t12 import TABLE1_METRICS

# The paper's figures (shared/paper, Tables 1-3) for the objects it and we both have.
PAPER_T1 = {  # min τ for the grasp chosen by μs, μg, μf, μm, N·m
    "sphere": (1.48, 1.48, 1.48, 1.48), "dumbbell": (1.29, 1.53, 1.29, 1.31),
    "ycb:YcbChipsCan": (1.54, 1.54, 1.55, 1.54), "ycb:YcbPowerDrill": (1.87, 2.13, 2.31, 2.03),
    "ycb:YcbHammer": (2.32, 2.32, 2.30, 2.33), "ycb:YcbBanana": (0.52, 0.52, 0.53, 0.52),
    "spiked_ball": (1.46, 1.46, 1.46, 1.46),
}
PAPER_T2 = {  # v_c, v_s (cm³), best μ of G_c, of G_s
    "sphere": (125.7, 125.7, 0.88, 0.88), "cube": (119.2, 120.3, 0.74, 0.74),
    "dumbbell": (138.2, 139.2, 0.94, 0.94), "ycb:YcbChipsCan": (136.2, 136.5, 0.91, 0.91),
    "ycb:YcbPowerDrill": (136.6, 158.3, 0.53, 0.87), "ycb:YcbHammer": (138.2, 163.2, 0.74, 0.76),
    "spiked_ball": (113.9, 125.4, 0.43, 0.43),
}
PAPER_T3 = {  # quality, # of grasps, misses, time, as fractions of PPO
    "adaptive_1": (0.7642, 0.6771, 0.9448, 0.2361),
    "adaptive_2": (0.8391, 0.8248, 0.8468, 0.4281),
    "adaptive_4": (0.9931, 0.9832, 0.7646, 0.7352),
    "adaptive_8": (1.0003, 1.0061, 0.7516, 1.7019),
}
SYMBOL = {"mu_s": "μs", "mu_g": "μg", "mu_f": "μf", "mu_m": "μm",
          "torque_margin_ratio": "margin"}


def _f(value: Any, digits: int = 2) -> str:
    if value is None:
        return "—"
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return str(value)


def _pct(value: float | None) -> str:
    return "—" if value is None else f"{100 * value:.1f} %"


def table1(rows: dict[str, Any]) -> list[str]:
    out = ["#### Table 1: minimum closing effort (N·m) of the best grasp by each metric",
           "", "| object | by μs | by μg | by μf | by μm | by torque margin | paper by μs / μg "
           "/ μf / μm |", "|---|---|---|---|---|---|---|"]
    for name, t1 in rows["table1"].items():
        cells = []
        for metric in TABLE1_METRICS:
            entry = t1.get(metric)
            if entry is None:
                cells.append("—")
            else:
                effort = entry["min_closing_effort_nm"]
                mark = "≤ " if entry.get("holds_at_floor") else ""
                cells.append(f"{mark}{_f(effort)} ({SYMBOL[metric]} {_f(entry['value'])})"
                             if effort is not None else "drops")
        paper = PAPER_T1.get(name)
        out.append(f"| {name} | " + " | ".join(cells) + " | "
                   + (" / ".join(f"{v:.2f}" for v in paper) if paper else "—") + " |")
    return [*out, ""]


def table2(rows: dict[str, Any]) -> list[str]:
    out = ["#### Table 2: G_c (baseline) against G_s (haptic) on one pose grid", "",
           "| object | v_c cm³ | v_s cm³ | G_c poses G_s holds | best μs G_c | best μs G_s "
           "| best μg c / s | paper v_c / v_s | paper μ c / s |",
           "|---|---|---|---|---|---|---|---|---|"]
    for row in rows["table2"]:
        c, s = row["baseline"], row["haptic"]
        paper = PAPER_T2.get(row["object"])
        out.append(
            f"| {row['object']} | {_f(c['volume_cm3'], 1)} | {_f(s['volume_cm3'], 1)} | "
            f"{_pct(row['contained_share'])} ({row['lost_by_haptic']} lost) | "
            f"{_f(c['best_mu_s'])} | {_f(s['best_mu_s'])} | "
            f"{_f(c['best_mu_g'])} / {_f(s['best_mu_g'])} | "
            + (f"{paper[0]} / {paper[1]} | {paper[2]} / {paper[3]} |" if paper else "— | — |"))
    return [*out, ""]


def _fraction_rows(labels: dict[str, dict[str, float | None]], with_paper: bool) -> list[str]:
    out = []
    for label, fr in labels.items():
        paper = PAPER_T3.get(label) if with_paper else None
        cells = " | ".join(f"{_pct(fr[k])} ({_pct(fr.get(f'{k}_median'))})"
                           for k in ("quality", "grasps", "misses", "time"))
        out.append(f"| {label} | {cells} | "
                   + (" / ".join(_pct(v) for v in paper) if paper else "—") + " |")
    return out


def _qgmt(r: dict[str, Any]) -> str:
    return (f"{r['quality_mu_s']:.3f} / {r['grasps']} / {r['misses']} / "
            f"{r['time_s']:.1f}")


def table3(rows: dict[str, Any]) -> list[str]:
    fr = rows["table3_fractions"]
    head = ["| explorer | quality | # of grasps | misses | time | paper quality / grasps / "
            "misses / time |", "|---|---|---|---|---|---|"]
    note = ("Each cell: the sum over the objects divided by PPO's (mean of its seeds) sum, "
            "and in brackets the median of the per-object fractions.")
    out = ["#### Table 3 at matched evaluations: each explorer as a fraction of PPO with the "
           "same number of evaluations", "", note, "", *head,
           *_fraction_rows(fr["matched"], with_paper=False), "",
           "#### Table 3 in the paper's layout: every adaptive run against PPO with adaptive at "
           f"{max(int(k) for k in next(iter(rows['table3'].values()))['matched'])} rolls' "
           "evaluations", "", note, "", *head,
           *_fraction_rows(fr["paper_layout"], with_paper=True), "",
           "#### Table 3, absolute (per object): best μs / grasps / misses / time s", "",
           "| object | rolls k | E_k | adaptive | PPO mean ± sd (seeds) | CMA-ES | random | "
           "adaptive first grasp s |", "|---|---|---|---|---|---|---|---|"]
    for name, t3 in rows["table3"].items():
        for k, m in t3["matched"].items():
            a, p = t3["runs"][f"adaptive_{k}"], m["ppo"]
            ppo = (f"{p['quality_mu_s']:.3f} ± {p['quality_mu_s_std']:.3f} / "
                   f"{p['grasps']:.1f} ± {p['grasps_std']:.1f} / {p['misses']:.1f} ± "
                   f"{p['misses_std']:.1f} / {p['time_s']:.1f} ± {p['time_s_std']:.1f} "
                   f"({p['seeds']})")
            out.append(f"| {name} | {k} | {m['budget']} | {_qgmt(a)} | {ppo} | "
                       f"{_qgmt(m['runs']['cmaes'])} | {_qgmt(m['runs']['random'])} | "
                       f"{_f(a['time_to_first_grasp_s'], 1)} |")
    out += ["", "(paper, PPO absolute: quality 0.78, 6234.53 grasps, 4527.64 misses, "
            "34.65 min per object)"]
    return out


def markdown(rows: dict[str, Any]) -> str:
    """The tables of a results file's rows that it has, ours beside the paper's."""
    out: list[str] = []
    if rows.get("table1"):
        out += table1(rows)
    if rows.get("table2"):
        out += table2(rows)
    if rows.get("table3") and "matched" in next(iter(rows["table3"].values())):
        out += table3(rows)
    return "\n".join(out)
