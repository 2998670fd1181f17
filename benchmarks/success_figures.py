"""The figures of bench_success_calibration: survival of each ranking's picks, calibration,
Brier score, AUC, false certifications, extra evaluations; and the reliability diagram."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.stats import beta, rankdata

LEVEL = 0.9
CONFIDENCE = 0.95


def auc(scores: list[float], positive: list[bool]) -> float | None:
    """Area under the ROC curve (Mann–Whitney, ties counted half); None without both
    classes."""
    y = np.asarray(positive, dtype=bool)
    n1, n0 = int(y.sum()), int((~y).sum())
    if n1 == 0 or n0 == 0:
        return None
    ranks = rankdata(np.asarray(scores, dtype=float))
    return float((ranks[y].sum() - n1 * (n1 + 1) / 2) / (n1 * n0))


def _score(row: dict, name: str) -> float:
    if name == "p_success":
        return row["lower"] + 1e-6 * row["p"]
    if name == "robust":
        return (row["robust_s"] or 0.0) + 1e-3 * (row["robust_q"] or 0.0)
    if name == "mu_s":
        return row["mu_s"]
    return row["torque_margin"] or 0.0


def fresh_rejects(row: dict) -> bool:
    """The fresh draws contradict a certification: their one-sided Clopper–Pearson upper
    bound (95 %) lies below the level. A claim that is true is contradicted at most 5 % of the
    time, where a fresh frequency below the level happens up to half the time at P = 0.9."""
    n = row["fresh_n"]
    k = round(row["fresh_survival"] * n)
    upper = 1.0 if k >= n else float(beta.ppf(CONFIDENCE, k + 1, n - k))
    return upper < LEVEL


def _mean(xs: list[float]) -> float | None:
    return round(float(np.mean(xs)), 4) if xs else None


def _pooled(rows: list[dict], rankings: tuple[str, ...]) -> dict[str, float | int | None]:
    """Calibration (poses with n ≥ 30), Brier score, each ranking's AUC for fresh survival
    ≥ the level, and the certified poses with the share of them that fell below it."""
    out: dict[str, float | int | None] = {}
    big = [r for r in rows if r["n"] >= 30]
    out["calibration_mae"] = _mean([abs(r["p"] - r["fresh_survival"]) for r in big])
    out["brier"] = _mean([r["p"] ** 2 - 2 * r["p"] * r["fresh_survival"] + r["fresh_survival"]
                          for r in rows if r["n"]])
    good = [r["fresh_survival"] >= LEVEL for r in rows]
    for name in rankings:
        a = auc([_score(r, name) for r in rows], good)
        out[f"auc_{name}"] = None if a is None else round(a, 4)
    cert = [r for r in rows if r["certified"]]
    out["certified_poses"] = len(cert)
    out["false_certification_share"] = (
        round(sum(r["fresh_survival"] < LEVEL for r in cert) / len(cert), 4) if cert else None)
    out["false_certification_rejected_share"] = (
        round(sum(fresh_rejects(r) for r in cert) / len(cert), 4) if cert else None)
    return out


def one(res: dict, rankings: tuple[str, ...]) -> dict:
    """The figures of one object under one model."""
    rows = {r["key"]: r for r in res["rows"]}
    out: dict[str, float | int | None] = {}
    for r in rankings:
        top = res["overall"][r]
        out[f"top1_fresh_survival_{r}"] = None if top is None else rows[top]["fresh_survival"]
        picks = [k for ks in res["picks"][r].values() for k in ks]
        out[f"top3_fresh_survival_{r}"] = _mean([rows[k]["fresh_survival"] for k in picks])
    scored = list(rows.values())
    out.update(_pooled(scored, rankings))
    out["calibration_poses"] = sum(1 for r in scored if r["n"] >= 30)
    out["certified_in_overall_top"] = bool(
        res["overall"]["p_success"] and rows[res["overall"]["p_success"]]["certified"])
    out["extra_evaluation_share"] = round(res["draws"]["run"] / res["evaluations"], 4)
    out["scored_poses"] = len(scored)
    out["held_at_all_fresh_mean"] = _mean([r["fresh_held_at_all"] for r in scored])
    return out


def figures_of(results: list[dict], rankings: tuple[str, ...]) -> tuple[dict, dict]:
    """Pooled figures (means over object × model; shares over all poses) and the per object
    and model ones."""
    detail = {f"{r['object']}.{r['model'].split(':')[0]}": one(r, rankings) for r in results}
    figures: dict[str, float | None] = {}
    for r in rankings:
        for top in ("top1", "top3"):
            name = f"{top}_fresh_survival_{r}"
            figures[name] = _mean([d[name] for d in detail.values() if d[name] is not None])
    rows = [row for r in results for row in r["rows"]]
    figures.update(_pooled(rows, rankings))
    figures["extra_evaluation_share"] = round(
        sum(r["draws"]["run"] for r in results) / sum(r["evaluations"] for r in results), 4)
    figures["scored_poses"] = len(rows)
    for key, d in detail.items():
        for name, value in d.items():
            figures[f"{key}.{name}"] = value
    return figures, detail


def reliability_png(results: list[dict], path: Path) -> None:
    """Predicted P (k/n, poses with n ≥ 30) against fresh survival, in 10 bins, per model."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 5))
    ax.plot([0, 1], [0, 1], color="grey", lw=1, ls="--", label="perfect calibration")
    models = sorted({r["model"].split(":")[0] for r in results})
    for model in models:
        rows = [row for r in results if r["model"].startswith(model) for row in r["rows"]
                if row["n"] >= 30]
        if not rows:
            continue
        p = np.array([r["p"] for r in rows])
        f = np.array([r["fresh_survival"] for r in rows])
        bins = np.minimum((p * 10).astype(int), 9)
        xs, ys, ns = [], [], []
        for b in range(10):
            sel = bins == b
            if sel.any():
                xs.append(p[sel].mean())
                ys.append(f[sel].mean())
                ns.append(int(sel.sum()))
        ax.plot(xs, ys, marker="o", label=f"{model} ({len(rows)} poses)")
        for x, y, n in zip(xs, ys, ns, strict=True):
            ax.annotate(str(n), (x, y), textcoords="offset points", xytext=(4, -10), fontsize=7)
    ax.set_xlabel("predicted P(success) = k/n of the run's draws")
    ax.set_ylabel("fresh survival (new draws, another seed)")
    ax.set_xlim(0, 1.02)
    ax.set_ylim(0, 1.02)
    ax.set_title("Reliability of P(success); numbers: poses per bin")
    ax.legend(loc="upper left", fontsize=8)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
