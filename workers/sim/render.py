"""Pictures of a simulated grasp with pybullet's TinyRenderer (headless, no screen)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pybullet as p
from PIL import Image


def render_scene(client: int, target: np.ndarray, path: Path, *, distance: float = 0.35,
                 yaw: float = 45.0, pitch: float = -25.0, size: tuple[int, int] = (640, 480)
                 ) -> Path:
    width, height = size
    view = p.computeViewMatrixFromYawPitchRoll(target.tolist(), distance, yaw, pitch, 0.0, 2,
                                               physicsClientId=client)
    projection = p.computeProjectionMatrixFOV(45.0, width / height, 0.01, 5.0,
                                              physicsClientId=client)
    _, _, rgba, _, _ = p.getCameraImage(width, height, view, projection,
                                        renderer=p.ER_TINY_RENDERER,
                                        lightDirection=[0.4, -0.6, 1.0],
                                        physicsClientId=client)
    image = np.reshape(np.asarray(rgba, dtype=np.uint8), (height, width, 4))[:, :, :3]
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(image).save(path)
    return path
