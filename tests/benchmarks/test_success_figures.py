"""The calibration benchmark's test of a certification against fresh draws, on binomial counts
whose truth is known."""

from __future__ import annotations

from scipy.stats import binom

from benchmarks.success_figures import fresh_rejects


def _rejection_rate(p: float, n: int) -> float:
    """Exact probability that n fresh draws of a pose with true P = p contradict its claim."""
    return sum(binom.pmf(k, n, p) for k in range(n + 1)
               if fresh_rejects({"fresh_n": n, "fresh_survival": k / n}))


def test_a_true_claim_is_contradicted_at_most_five_percent_of_the_time() -> None:
    for n in (30, 100, 300):
        for p in (0.9, 0.95, 0.99):
            assert _rejection_rate(p, n) <= 0.05


def test_a_false_claim_is_contradicted_often_with_enough_draws() -> None:
    assert _rejection_rate(0.7, 100) > 0.99
    assert _rejection_rate(0.8, 100) > 0.5


def test_a_fresh_frequency_just_below_the_level_is_no_contradiction() -> None:
    assert not fresh_rejects({"fresh_n": 100, "fresh_survival": 0.88})
    assert fresh_rejects({"fresh_n": 100, "fresh_survival": 0.80})
