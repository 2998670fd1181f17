"""The race in the certification's terms: draws by key, successes by grasp type, looks."""

from __future__ import annotations

from graspscape.services.coordinator.exploration import racing
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.mapspace import success
from graspscape.shared.specs.uncertainty import UncertaintyModel


def _pose(key: str, theta: float, viable: bool, digits: tuple[str, ...]) -> StoredPose:
    return StoredPose(key=key, theta=theta, phi=0.5, r=0.01, roll=0.0, pitch=0.0, yaw=0.0,
                      viable=viable, outcome="held" if viable else "dropped", mu_s=0.5,
                      digits=frozenset(digits))


def test_outcomes_in_draw_order_up_to_the_first_missing() -> None:
    centre = _pose("c", 1.0, True, ("A", "B", "C"))
    seq = racing.draw_poses(centre, UncertaintyModel(preset="lab"), 0.05, 5)
    assert seq == racing.draw_poses(centre, UncertaintyModel(preset="lab"), 0.05, 5)
    stored = {seq[0].key(): _pose(seq[0].key(), 1.0, True, ("A", "B", "C")),
              seq[1].key(): _pose(seq[1].key(), 1.0, True, ("A", "B")),  # another grasp type
              seq[2].key(): _pose(seq[2].key(), 1.0, False, ()),
              seq[4].key(): _pose(seq[4].key(), 1.0, True, ("A", "B", "C"))}
    assert racing.outcomes(centre, seq, stored) == [True, False, False]  # draw 3 missing


def test_race_round_plans_each_chosen_candidate_to_its_next_look() -> None:
    model = UncertaintyModel(preset="lab")
    good, bad = _pose("g", 1.0, True, ("A",)), _pose("b", 2.0, True, ("A",))
    samples = {(0,): good, (1,): bad}
    seqs = {p: racing.draw_poses(s, model, 0.05, success.LOOKS[-1]) for p, s in samples.items()}
    stored = {}
    for q in seqs[(0,)][:12]:
        stored[q.key()] = _pose(q.key(), 1.0, True, ("A",))
    for q in seqs[(1,)][:12]:
        stored[q.key()] = _pose(q.key(), 2.0, False, ())
    cands = racing.assess([(0,), (1,)], samples, seqs.__getitem__, stored, level=0.9)
    assert [(c.estimate.k, c.estimate.n) for c in cands] == [(12, 12), (0, 12)]
    planned = racing.race_round(cands)
    # the leader to 24 draws; the refuted one gets nothing
    assert planned == [((0,), list(seqs[(0,)][12:24]))]
    assert racing.best(cands).point == (0,)
    drawn = racing.race_draws(cands)
    assert [i for i, _ in drawn[0][1]] == list(range(12, 24))


def test_a_draw_succeeds_only_where_each_listed_engine_held_the_grasp_type() -> None:
    centre = _pose("c", 1.0, True, ("A", "B"))

    def drawn(**engines: tuple[bool, tuple[str, ...]]) -> StoredPose:
        return StoredPose(key="d", theta=1.0, phi=0.5, r=0.01, roll=0.0, pitch=0.0, yaw=0.0,
                          viable=all(h for h, _ in engines.values()), outcome="held",
                          mu_s=0.0, engines={k: (h, frozenset(d)) for k, (h, d) in
                                             engines.items()})

    both = drawn(pybullet=(True, ("A", "B")), mujoco=(True, ("A", "B")))
    assert racing.success_of(centre, both, ("pybullet", "mujoco"))
    other_type = drawn(pybullet=(True, ("A", "B")), mujoco=(True, ("A",)))
    assert not racing.success_of(centre, other_type, ("pybullet", "mujoco"))
    assert racing.success_of(centre, other_type, ("pybullet",))
    # An engine the draw never ran in is no success: a claim names only engines simulated.
    assert not racing.success_of(centre, drawn(pybullet=(True, ("A", "B"))),
                                 ("pybullet", "mujoco"))


def test_the_model_tells_its_draws_apart_and_lists_each_engine_once() -> None:
    import pytest
    from pydantic import ValidationError

    assert UncertaintyModel(preset="field").friction_scale == (0.5, 1.0)
    with pytest.raises(ValidationError, match="pose error"):
        UncertaintyModel(preset="none", friction_scale=(0.5, 1.0))
    with pytest.raises(ValidationError, match="twice"):
        UncertaintyModel(engines=("pybullet", "pybullet"))
    with pytest.raises(ValidationError):
        UncertaintyModel(engines=("bullet3",))
    both = UncertaintyModel(preset="lab", engines=("pybullet", "mujoco"))
    assert "held in pybullet and mujoco" in both.describe()
