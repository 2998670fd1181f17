"""Table 3 at matched budgets (benchmarks/paper_tables_t3.py): the baselines get adaptive's
evaluation count, and the fractions of PPO are taken against the right PPO in each layout.
Pure functions on written-out runs: no simulation (the slow test_paper_tables runs them)."""

from __future__ import annotations

import pytest

from benchmarks.paper_tables_docs import markdown
from benchmarks.paper_tables_sizes import SIZES, YCB_BY_COST, cheapest_first
from benchmarks.paper_tables_t3 import baselines, ppo_summary, summarise_table3


def _run(q: float, grasps: int, misses: int, time_s: float) -> dict:
    return {"evaluations": grasps + misses, "quality_mu_s": q, "grasps": grasps,
            "misses": misses, "time_s": time_s, "time_to_first_grasp_s": 0.5,
            "grasp_types": 1}


def _matched(budget: int, ppo: list[dict], cmaes: dict, random: dict) -> dict:
    runs = {f"ppo_seed{i}": r for i, r in enumerate(ppo)} | {"cmaes": cmaes, "random": random}
    return {"budget": budget, "runs": runs, "ppo": ppo_summary(runs)}


def test_every_baseline_gets_the_budget_it_is_given() -> None:
    runs = baselines(SIZES["small"], 37)
    assert [label for label, _ in runs] == ["ppo_seed0", "ppo_seed1", "ppo_seed2", "cmaes",
                                            "random"]
    assert all(strategy["poses"] == 37 for _, strategy in runs)
    assert {strategy["seed"] for label, strategy in runs if label.startswith("ppo")} == {0, 1, 2}
    # Random search's rounds stay within its spec's 1-100 at any budget.
    assert dict(baselines(SIZES["small"], 3))["random"]["rounds"] == 1
    assert dict(baselines(SIZES["small"], 10_000))["random"]["rounds"] == 100


def test_fractions_are_taken_against_matched_and_largest_budget_ppo() -> None:
    # One object, rolls 1 and 2: adaptive spent 6 and 12 evaluations.
    t3 = {"obj": {
        "runs": {"adaptive_1": _run(0.8, 4, 2, 3.0), "adaptive_2": _run(0.9, 8, 4, 6.0)},
        "matched": {
            "1": _matched(6, [_run(0.4, 2, 4, 3.0), _run(0.6, 4, 2, 5.0), _run(0.5, 3, 3, 4.0)],
                          _run(0.5, 3, 3, 2.0), _run(1.0, 6, 0, 8.0)),
            "2": _matched(12, [_run(0.9, 6, 6, 12.0)] * 3, _run(0.9, 6, 6, 6.0),
                          _run(0.45, 3, 9, 24.0)),
        }}}
    fr, figures = summarise_table3(t3, (1, 2))
    # Matched: adaptive at 1 roll against PPO with 6 evaluations (mean quality 0.5, 3
    # grasps, 3 misses, 4 s).
    a1 = fr["matched"]["adaptive_1"]
    assert (a1["quality"], a1["time"]) == (1.6, 0.75)
    assert (a1["grasps"], a1["misses"]) == (pytest.approx(4 / 3, abs=1e-4),
                                            pytest.approx(2 / 3, abs=1e-4))
    assert a1["quality_median"] == a1["quality_mean"] == 1.6  # one object
    c2 = fr["matched"]["cmaes@E_2"]
    assert [c2[k] for k in ("quality", "grasps", "misses", "time")] == [1.0, 1.0, 1.0, 0.5]
    assert fr["matched"]["random@E_1"]["quality"] == 2.0
    # The paper's layout: both adaptive runs against PPO with 12 evaluations.
    p1 = fr["paper_layout"]["adaptive_1"]
    assert [p1[k] for k in ("quality", "grasps", "misses", "time")] == [
        pytest.approx(0.8 / 0.9, abs=1e-4), pytest.approx(4 / 6, abs=1e-4),
        pytest.approx(2 / 6, abs=1e-4), 0.25]
    # Adaptive at 1 roll: 4 s against PPO's 12 s at 12 evaluations, not ≤ 1/3 of it.
    assert figures["t3.paper_layout.adaptive_1.objects_meeting_target.time"] == 1
    assert figures["t3.paper_layout.adaptive_1.objects_meeting_target.all"] == 0
    assert fr["paper_layout"]["adaptive_2"]["time"] == 0.5
    assert figures["t3.obj.ppo@E_1.mean.quality_mu_s"] == 0.5
    assert figures["t3.obj.ppo@E_1.std.quality_mu_s"] == pytest.approx(0.0816, abs=1e-4)
    assert figures["t3.adaptive_max_time_to_first_grasp_s"] == 0.5
    # The docs' tables render both layouts and one absolute row per roll count.
    text = markdown({"table1": {}, "table2": [], "table3": t3, "table3_fractions": fr})
    assert ("| adaptive_1 | 160.0 % (160.0 %) | 133.3 % (133.3 %) | 66.7 % (66.7 %) | "
            "75.0 % (75.0 %) | — |") in text
    assert "| adaptive_1 | 88.9 % (88.9 %) | 66.7 % (66.7 %) |" in text
    assert text.count("| obj | ") == 2


def test_all_objects_run_cheapest_first() -> None:
    names = ("ycb:YcbStrawberry", "ycb:Zzz", "ycb:YcbCrackerBox", "ycb:YcbBanana")
    assert cheapest_first(names) == ("ycb:YcbCrackerBox", "ycb:YcbBanana",
                                     "ycb:YcbStrawberry", "ycb:Zzz")
    assert len(set(YCB_BY_COST)) == 12


def test_a_near_zero_ppo_on_one_object_does_not_make_the_headline() -> None:
    # Two objects, one roll count: on "a" PPO's best μs is 0.001 (a barely held grasp), on
    # "b" 0.5; adaptive finds 0.9 on both.
    def obj(ppo_q: float) -> dict:
        return {"runs": {"adaptive_1": _run(0.9, 3, 3, 2.0)},
                "matched": {"1": _matched(6, [_run(ppo_q, 1, 5, 2.0)] * 3,
                                          _run(0.5, 1, 5, 2.0), _run(0.5, 1, 5, 2.0))}}
    fr, _ = summarise_table3({"a": obj(0.001), "b": obj(0.5)}, (1,))
    q = fr["matched"]["adaptive_1"]
    assert q["quality"] == pytest.approx(1.8 / 0.501, abs=1e-4)  # ratio of the sums
    assert q["quality_mean"] == pytest.approx((900 + 1.8) / 2, abs=1e-3)  # the blow-up
    assert q["quality_median"] == pytest.approx((900 + 1.8) / 2, abs=1e-3)  # two: their mean
