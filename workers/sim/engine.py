"""The seam between the evaluation and a physics engine.

Policies, the start pose and the metrics act on a *scene* and its *hand* through the methods
below; `workers/sim/scene.py` + `gripper/hand.py` implement them on pybullet, `mj/scene.py` +
`mj/hand.py` on MuJoCo. The engine-specific rest (loading, saved states, the trajectory's
release and gravity, the μs probes' rollouts, the robustness tests' trials: robustness.py's
BulletTrials, mj/robustness.py's MjTrials) lives in each engine's evaluator:
`evaluate.Evaluator` (pybullet) and `mj/evaluate.MjEvaluator`. `make_evaluator` picks one by
`SimSettings.engine`; nothing else branches on the engine.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Callable
from contextlib import AbstractContextManager
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np
from graspscape.shared.specs.sim import ENGINE_NAMES

if TYPE_CHECKING:
    from graspscape.shared.specs.gripper import AnyGripperSpec
    from graspscape.shared.specs.sim import SimSettings
    from graspscape.workers.sim.objects import PreparedObject


class HandLike(Protocol):
    link_names: dict[int, str]
    finger_joints: list[int]
    mass: float

    def frame_pose(self) -> tuple[np.ndarray, np.ndarray]: ...
    def reset_open(self, spread: float, effort: float, hold_factor: float) -> None: ...
    def begin_closing(self, speed: float) -> None: ...
    def update_closing(self, stall_tolerance: float,
                       touching: frozenset[int] = frozenset()) -> bool: ...
    def settle(self, touching: frozenset[int]) -> None: ...
    def joint_angles(self) -> dict[str, float]: ...
    def max_finger_torque(self) -> float: ...


class SceneLike(Protocol):
    hand: HandLike
    offset: np.ndarray
    dt: float

    def drive_to(self, position: np.ndarray, rotation: np.ndarray,
                 max_force: float = ...) -> None: ...
    def step(self) -> None: ...
    def in_contact(self) -> bool: ...
    def palm_in_contact(self) -> bool: ...
    def touching_links(self) -> frozenset[int]: ...
    def contacts(self) -> list: ...
    def object_pose(self) -> tuple[np.ndarray, np.ndarray]: ...
    def pair_friction(self, link: int) -> float: ...
    def place_hand(self, position: np.ndarray, rotation: np.ndarray) -> None: ...
    def penetrating(self, tolerance: float) -> bool: ...
    # A P(success) draw's friction and mass scales, put back when the block ends (samples.py).
    def scaled_object(self, friction: float, mass: float
                      ) -> AbstractContextManager[None]: ...

    # The haptic policy's proximity sensors and finite-difference probes.
    def link_distances(self, links: list[int], max_distance: float) -> np.ndarray: ...
    def joint_limits(self, joints: list[int]) -> np.ndarray: ...
    def joint_positions(self, joints: list[int]) -> np.ndarray: ...
    def parent_link(self, link: int) -> int: ...
    def probing_joints(self) -> AbstractContextManager[Callable[[], None]]: ...
    def probing_base(self) -> AbstractContextManager[None]: ...
    def teleport_joint(self, joint: int, q: float) -> None: ...
    def teleport_frame(self, position: np.ndarray, rotation: np.ndarray) -> None: ...


def available_engines() -> tuple[str, ...]:
    """The engines this machine can run (a worker advertises them when it asks for tiles)."""
    have = {"pybullet": importlib.util.find_spec("pybullet") is not None,
            "mujoco": importlib.util.find_spec("mujoco") is not None}
    return tuple(name for name in ENGINE_NAMES if have[name])


def make_evaluator(prepared: PreparedObject, gripper: AnyGripperSpec, settings: SimSettings,
                   *, work_dir: Path):
    if settings.engine == "mujoco":
        if settings.table is not None:
            raise ValueError("a table (support 'plane') is simulated on pybullet only; "
                             "set the engine to pybullet")
        from graspscape.workers.sim.mj.evaluate import MjEvaluator

        return MjEvaluator(prepared, gripper, settings, work_dir=work_dir)
    from graspscape.workers.sim.evaluate import Evaluator

    return Evaluator(prepared, gripper, settings, work_dir=work_dir)
