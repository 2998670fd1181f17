"""The PPO explorer's gymnasium environment: one pose evaluation per episode.

The paper's PPO baseline (section IV.A) takes an initial relative pose as its action and gets
back the grasp's quality, 0 when no grasp held, with the reward w_s·quality − w_f·τ_m (τ_m the
largest joint effort the grasp used along the trajectory, Nm). Here an episode is one step:
the observation is constant, the action is a point of the same continuous search space as the
cmaes strategy's (strategies/cmaes.py: an approach vector normalised to a direction, a start
gap folded into [r_min, r_max], a roll turn when the grid has several rolls), and the reward
is `reward(...)` of the evaluated pose. PPO thus learns a Gaussian distribution over poses
(a contextual bandit with one context), as a policy-gradient search over the pose space.

`PoseEnv` evaluates through any callable (a worker's evaluate_pose, a test's oracle) and runs
under stable-baselines3's own `learn`; the `ppo` strategy (strategies/ppo.py) drives the same
policy with rollouts the scheduler evaluates on the workers. The force limit stays a
setting of the exploration (`settings`), not part of the action: every pose of one
exploration is evaluated under one simulation setting, so that the map is one map.

Needs the optional extra `rl` (gymnasium); `require_rl()` says how to install it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from graspscape.services.coordinator.exploration.strategies.cmaes import decode
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.pose import Pose

INSTALL_HINT = (
    "the 'ppo' strategy needs the optional RL extra (torch, stable-baselines3, gymnasium): "
    "install torch's CPU build first, `pip install torch --index-url "
    "https://download.pytorch.org/whl/cpu`, then `pip install -e '.[rl]'` (README, 'Set up')"
)


class RLExtraMissing(ImportError):
    """The optional `rl` extra is not installed."""


def require_rl() -> None:
    """Raise RLExtraMissing, saying how to install the extra, when it is not installed."""
    try:
        import gymnasium  # noqa: F401
        import stable_baselines3  # noqa: F401
        import torch  # noqa: F401
    except ImportError as e:
        raise RLExtraMissing(f"{INSTALL_HINT} ({e})") from e


def action_dim(spec: ExplorationSpec) -> int:
    """(v_x, v_y, v_z, u_r) and, when the grid has several rolls, u_roll."""
    return 5 if spec.grid.attitudes.rolls > 1 else 4


def action_pose(action: np.ndarray, spec: ExplorationSpec) -> Pose:
    """The pose an action stands for: the cmaes decoding (no edge at the poles, the azimuth
    wrap or the r ends), with u_r and u_roll shifted so that an action of 0 is the middle of
    the r range and of the roll turn."""
    a = np.asarray(action, dtype=float).copy()
    a[3] = (a[3] + 1.0) / 2.0
    if len(a) > 4:
        a[4] = (a[4] + 1.0) / 2.0
    return decode(a, spec)


def reward(viable: bool, quality: float, effort_nm: float | None, w_s: float, w_f: float
           ) -> float:
    """The paper's reward: w_s·quality − w_f·τ_m for a held grasp, 0 when none held."""
    if not viable:
        return 0.0
    effort = 0.0 if effort_nm is None or not math.isfinite(effort_nm) else float(effort_nm)
    return w_s * float(quality) - w_f * effort


def make_env(spec: ExplorationSpec, evaluate: Callable[[Pose], tuple[bool, float, float]],
             w_s: float = 1.0, w_f: float = 0.0) -> Any:
    """A PoseEnv (gymnasium.Env) over `evaluate(pose) -> (viable, quality, effort_nm)`."""
    require_rl()
    import gymnasium as gym

    class PoseEnv(gym.Env):
        """One pose evaluation per episode; the observation carries no information."""

        metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012

        def __init__(self) -> None:
            dim = action_dim(spec)
            # Nominal bounds: stable-baselines3's learn clips actions to them; the decoding
            # itself is defined (and continuous) everywhere.
            self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(dim,), dtype=np.float32)
            self.observation_space = gym.spaces.Box(0.0, 1.0, shape=(1,), dtype=np.float32)
            self.poses: list[Pose] = []

        def reset(self, *, seed: int | None = None, options: dict | None = None
                  ) -> tuple[np.ndarray, dict]:
            super().reset(seed=seed)
            return OBSERVATION.copy(), {}

        def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
            pose = action_pose(action, spec)
            self.poses.append(pose)
            viable, quality, effort = evaluate(pose)
            r = reward(viable, quality, effort, w_s, w_f)
            return OBSERVATION.copy(), r, True, False, {"pose": pose, "viable": viable}

    return PoseEnv()


# The one observation: PPO's policy sees the same input at every step.
OBSERVATION = np.ones(1, dtype=np.float32)
