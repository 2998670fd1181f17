"""The ppo strategy: stable-baselines3's PPO over the pose space, a baseline (issue 20).

The environment is ppo_env.PoseEnv: one pose evaluation per episode, the action a point of
the continuous pose space, the reward the paper's w_s·quality − w_f·τ_m (0 when no grasp
held). Here the scheduler, not stable-baselines3's `learn`, collects the rollouts, so that
they run on every worker: rollout k is round k, its `batch` actions sampled from the policy
at once and queued as one round of poses; once all of it is stored, its rewards go into
PPO's rollout buffer (one-step episodes: the advantage is reward − value) and PPO's own
`train()` runs its clipped-surrogate epochs; then the next rollout is sampled. The budget
`poses` counts every sampled pose; the last rollout is cut to what is left, and is not
trained on.

Quality of a stored pose: the spec's objective (the torque margin ratio, /best's default
rank, where stored, else μs; or μs alone), as for cmaes; effort: its stored effort_max_nm.

State. Like cmaes, `next_round` replays every finished rollout from the seed, each with the
rewards the store holds for its poses (a missing pose, whose tile failed, scores 0), so that
the run is a function of the spec and the stored results whatever the workers, interleaving
or restarts. The network's initial weights, the action samples and the minibatch shuffles
draw from generators of the search's own, never from torch's or numpy's global ones, and
torch runs single-threaded inside, so that a replay gives the same floats. The last
replay's search is kept in memory and resumed while the rewards it was told are still the
stored ones (the same search, sooner: a replay costs one `train()` per rollout).

Needs the optional extra `rl`; without it a submission is refused (422) saying how to
install it.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Generator, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from graspscape.services.coordinator.errors import InvalidInput
from graspscape.services.coordinator.exploration.strategies.base import Batch, Planned, Stage
from graspscape.services.coordinator.exploration.strategies.cmaes import quality
from graspscape.services.coordinator.exploration.strategies.ppo_env import (
    OBSERVATION,
    RLExtraMissing,
    action_pose,
    make_env,
    require_rl,
    reward,
)
from graspscape.services.coordinator.exploration.strategies.replay_cache import (
    Told,
    next_replayed_round,
)
from graspscape.services.coordinator.exploration.tiling import TilePlan, group_tiles
from graspscape.services.coordinator.state import current
from graspscape.services.coordinator.store.models import PoseRow
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.strategies import PpoStrategySpec
from sqlalchemy import select
from sqlalchemy.orm import Session

# Hidden layer of the policy and value networks: the observation is constant, so the
# networks only carry a learned mean (and value); a small layer is enough and trains fast.
HIDDEN = 32


@contextlib.contextmanager
def _torch_rng(state: Any) -> Iterator[Callable[[], Any]]:
    """Torch's global generator set to `state` (restored on exit), single-threaded; yields
    a function that returns the state reached."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with torch.random.fork_rng(devices=[]):
            torch.set_rng_state(state)
            yield torch.get_rng_state
    finally:
        torch.set_num_threads(threads)


def _seeded_buffer_class() -> type:
    from stable_baselines3.common.buffers import RolloutBuffer

    class SeededRolloutBuffer(RolloutBuffer):
        """PPO's rollout buffer, shuffling minibatches with a generator of its own (the
        stock one draws from numpy's global generator)."""

        rng: np.random.Generator = np.random.default_rng(0)

        def get(self, batch_size: int | None = None) -> Generator[Any, None, None]:
            assert self.full, "the rollout is not complete"
            n = self.buffer_size * self.n_envs
            indices = self.rng.permutation(n)
            if not self.generator_ready:
                for name in ("observations", "actions", "values", "log_probs", "advantages",
                             "returns"):
                    self.__dict__[name] = self.swap_and_flatten(self.__dict__[name])
                self.generator_ready = True
            size = batch_size or n
            for start in range(0, n, size):
                yield self._get_samples(indices[start:start + size])

    return SeededRolloutBuffer


@dataclass
class _Search:
    """PPO on the pose space, one rollout per round."""

    spec: ExplorationSpec
    strategy: PpoStrategySpec
    used: int = 0  # poses sampled so far, the budget's count
    rollouts: int = 0  # rollouts trained on
    model: Any = field(init=False)
    torch_state: Any = field(init=False)
    _pending: Any = field(init=False, default=None)

    def __post_init__(self) -> None:
        import torch
        from stable_baselines3 import PPO
        from stable_baselines3.common.logger import configure

        s = self.strategy
        gen = torch.Generator().manual_seed(s.seed)
        with _torch_rng(gen.get_state()) as reached:
            self.model = PPO(
                "MlpPolicy", make_env(self.spec, _never, s.w_s, s.w_f),
                learning_rate=s.learning_rate, n_steps=s.batch,
                batch_size=max(2, s.batch // 4), n_epochs=s.epochs, gamma=1.0, gae_lambda=1.0,
                ent_coef=s.ent_coef, device="cpu", seed=None, verbose=0,
                rollout_buffer_class=_seeded_buffer_class(),
                policy_kwargs={"net_arch": {"pi": [HIDDEN], "vf": [HIDDEN]},
                               "log_std_init": s.log_std_init})
            self.torch_state = reached()
        self.model.rollout_buffer.rng = np.random.default_rng([s.seed, 1])
        self.model.set_logger(configure(None, []))

    def mark(self) -> tuple[Any, int]:
        return self.torch_state, self.used

    def restore(self, mark: tuple[Any, int]) -> None:
        self.torch_state, self.used = mark
        self._pending = None

    def ask(self) -> tuple[np.ndarray, list[Pose]]:
        """The next rollout's actions and poses, cut to the budget left (empty when spent)."""
        import torch

        left = self.strategy.poses - self.used
        if left <= 0:
            return np.zeros((0, 1)), []
        policy = self.model.policy
        policy.set_training_mode(False)
        obs = torch.as_tensor(np.repeat(OBSERVATION[None, :], self.strategy.batch, axis=0))
        with _torch_rng(self.torch_state) as reached, torch.no_grad():
            actions, values, log_probs = policy(obs)
            self.torch_state = reached()
        self._pending = (values, log_probs)
        xs = actions.numpy()[:left]
        self.used += len(xs)
        return xs, [action_pose(x, self.spec) for x in xs]

    def tell(self, xs: np.ndarray, rewards: list[float]) -> None:
        """Train on a whole rollout (PPO's train(): epochs of clipped-surrogate updates)."""
        import torch

        if len(xs) < self.strategy.batch:
            return  # the budget's last, cut rollout: nothing follows it
        values, log_probs = self._pending
        buffer = self.model.rollout_buffer
        buffer.reset()
        obs = OBSERVATION[None, :]
        for i, (x, r) in enumerate(zip(xs, rewards, strict=True)):
            buffer.add(obs, x[None, :], np.array([r], dtype=np.float32), np.array([True]),
                       values[i:i + 1], log_probs[i:i + 1])
        buffer.compute_returns_and_advantage(last_values=torch.zeros(1), dones=np.ones(1))
        with _torch_rng(self.torch_state) as reached:
            self.model.train()
            self.torch_state = reached()
        self.rollouts += 1
        self._pending = None


def _never(pose: Pose) -> tuple[bool, float, float]:
    raise AssertionError("the scheduler evaluates the ppo strategy's poses, not the env")


# Searches as the last replay left them, per exploration (strategies/replay_cache.py, on the
# coordinator's state: services/coordinator/state.py). A
# resumed search is taken out of the cache while it runs, so no two calls share one.


def _resume(cache_key: str | None, spec: ExplorationSpec, g: int,
            reward_of: Callable[[str], float]) -> tuple[_Search, Told]:
    kept = current().ppo_searches.resume(cache_key, g, reward_of, take=lambda snap: snap.search,
                                         pop=True)
    if kept is not None:
        return kept
    strategy = spec.strategy
    assert isinstance(strategy, PpoStrategySpec)
    return _Search(spec, strategy), []


def rollout(spec: ExplorationSpec, g: int, reward_of: Callable[[str], float],
            skip: Callable[[str], bool] = lambda key: False,
            cache_key: str | None = None) -> tuple[int, list[Pose]]:
    """Replay rollouts 0 … g − 1 (training on the rewards of their poses), then sample on
    until a rollout has a pose for which `skip` is false: (its index, its poses), or
    (index, []) when the budget is spent. With `cache_key`, resume from the last replay's
    search under that key where it still holds."""
    search, told = _resume(cache_key, spec, g, reward_of)
    while True:
        mark = search.mark() if len(told) >= g else None
        xs, poses = search.ask()
        if not poses or (mark is not None and not all(skip(p.key()) for p in poses)):
            if mark is not None:
                search.restore(mark)
                current().ppo_searches.keep(cache_key, search, told)
            return len(told), poses
        keys = [p.key() for p in poses]
        rewards = [reward_of(key) for key in keys]
        search.tell(xs, rewards)
        told.append((keys, rewards))


def pose_reward(row: Any, strategy: PpoStrategySpec) -> float:
    """A stored pose's reward: w_s·quality − w_f·effort when viable, else 0."""
    return reward(bool(row.viable), quality(row, strategy.objective), row.effort_max_nm,
                  strategy.w_s, strategy.w_f)


class PpoStrategy:
    reacts = True
    has_rounds = True

    def __init__(self, spec: ExplorationSpec) -> None:
        assert isinstance(spec.strategy, PpoStrategySpec)
        try:
            require_rl()
        except RLExtraMissing as e:
            raise InvalidInput(str(e), loc=("body", "strategy")) from e
        self.spec = spec
        self.strategy = spec.strategy

    def planned_poses(self) -> int:
        return self.strategy.poses

    def initial_work(self, session: Session, *, target_poses: int) -> list[TilePlan]:
        _, poses = rollout(self.spec, 0, lambda key: 0.0)
        return group_tiles(poses, target_poses=target_poses)

    def after_batch(self, batch: Batch) -> list[Planned]:
        return []  # a rollout is trained on only once all of it is stored: in next_round

    def next_round(self, batch: Batch) -> list[Planned]:
        values = self._rewards(batch.session, batch.exploration_id)
        return next_replayed_round(batch, self.spec, rollout, values, "ppo")

    def progress(self, batch: Batch, stage: Stage) -> None:
        return None  # off-lattice poses: no manifolds to refresh

    def _rewards(self, session: Session, eid: int) -> Mapping[str, float]:
        rows = session.execute(
            select(PoseRow.pose_key, PoseRow.viable, PoseRow.mu_s, PoseRow.torque_margin_ratio,
                   PoseRow.effort_max_nm)
            .where(PoseRow.exploration_id == eid))
        return {row.pose_key: pose_reward(row, self.strategy) for row in rows}


