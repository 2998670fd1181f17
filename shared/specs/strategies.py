"""How an exploration chooses its poses: the strategies a spec names (`strategy.name`), each
with its budget and settings; the coordinator's strategies/ package runs them."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field


class AdaptiveStrategySpec(BaseModel):
    """The paper's exploration: the coarse grid, border refinement down to
    `refinement.levels`, the shortcuts, local search rounds (docs/design/exploration.md)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: Literal["adaptive"] = "adaptive"


class GridStrategySpec(BaseModel):
    """The dense grid at the finest level of the lattice (`refinement.levels` halvings of
    Δθ and Δr): every pose evaluated, no refinement, no search, no shortcuts."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: Literal["grid"]


class RandomStrategySpec(BaseModel):
    """`poses` poses drawn uniformly over the pose space (directions uniform on the sphere,
    start gaps uniform in [r_min, r_max], attitudes uniform over the grid's list), repeatable
    from `seed`; handed out in `rounds` rounds of equal size, each once the previous one is
    stored (services/coordinator/exploration/strategies/random.py)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: Literal["random"]
    poses: int = Field(default=1000, ge=1, le=1_000_000, description="pose budget")
    seed: int = Field(default=0, ge=0, le=2**31 - 1)
    rounds: int = Field(default=1, ge=1, le=100, description="rounds the budget is split into")


class CmaesStrategySpec(BaseModel):
    """CMA-ES (the `cma` package) over the continuous pose space, maximising each pose's
    quality, with IPOP restarts; `poses` evaluations in all, asked a generation (one round)
    at a time and repeatable from `seed`
    (services/coordinator/exploration/strategies/cmaes.py)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: Literal["cmaes"]
    poses: int = Field(default=1000, ge=1, le=1_000_000, description="evaluation budget")
    seed: int = Field(default=0, ge=0, le=2**31 - 1)
    popsize: int | None = Field(
        default=None, ge=4, le=1000,
        description="poses per generation of the first run (None: cma's 4 + 3 ln n); IPOP "
        "doubles it at every restart")
    sigma0: float = Field(
        default=0.4, gt=0.0, le=2.0,
        description="initial step size, in units of the unit approach vector, of the r range "
        "and of one full roll turn")
    objective: Literal["rank", "mu_s"] = Field(
        default="rank",
        description="'rank': the default rank metric of /best (the torque margin ratio) where "
        "stored on the pose, else μs; 'mu_s': μs. A non-viable pose scores 0")


class PpoStrategySpec(BaseModel):
    """stable-baselines3's PPO over the continuous pose space (the paper's PPO baseline): one
    pose per episode, reward w_s·quality − w_f·τ_m (0 when no grasp held); a rollout of
    `batch` poses per round, trained on once all of it is stored; `poses` evaluations in all,
    repeatable from `seed`. Needs the optional extra `rl`
    (services/coordinator/exploration/strategies/ppo.py)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: Literal["ppo"]
    poses: int = Field(default=1000, ge=1, le=1_000_000, description="evaluation budget")
    seed: int = Field(default=0, ge=0, le=2**31 - 1)
    batch: int = Field(default=32, ge=4, le=4096,
                       description="poses per rollout (one round): PPO's n_steps")
    epochs: int = Field(default=10, ge=1, le=100, description="PPO epochs per rollout")
    learning_rate: float = Field(default=3e-3, gt=0.0, le=1.0)
    ent_coef: float = Field(default=0.0, ge=0.0, le=1.0, description="entropy bonus")
    log_std_init: float = Field(
        default=0.0, ge=-5.0, le=2.0,
        description="initial log standard deviation of the Gaussian policy, in action units "
        "(0: σ = 1, about the whole pose space)")
    w_s: float = Field(default=1.0, ge=0.0, le=100.0, description="weight of the quality")
    w_f: float = Field(default=0.05, ge=0.0, le=100.0,
                       description="weight of the largest joint effort τ_m, 1/Nm")
    objective: Literal["rank", "mu_s"] = Field(
        default="rank",
        description="the quality: 'rank', the torque margin ratio where stored on the pose, "
        "else μs; 'mu_s': μs")


StrategySpec = Annotated[
    AdaptiveStrategySpec | GridStrategySpec | RandomStrategySpec | CmaesStrategySpec
    | PpoStrategySpec,
    Field(discriminator="name"),
]
