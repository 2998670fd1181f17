"""How μs depends on how it is measured: halve each measurement choice and compare.

For a fixed set of held grasps (sphere and mug), μs is computed with the default metric
settings and with each of instants, window, perturbation size (linear and angular) and
characteristic length halved, and with the object moved by 1 µm, by (0.5, −0.3, 0.2) m and by
(10, 10, 1) m; and the estimator's anchor, a weld (workers/sim/calibration.py): its lowest
per-instant reading on each calibration object and its spread over the three places.
Reports, per variant, the mean |Δμs| and the Spearman rank correlation with the default.

    .venv/bin/python benchmarks/bench_metric_stability.py   # writes results/metric_stability.json
"""

from __future__ import annotations

import math

import numpy as np
from graspscape.shared.specs.gripper import load_gripper
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.sim import MetricSettings, SimSettings
from graspscape.workers.sim.calibration import (
    CALIBRATION_OBJECTS,
    CALIBRATION_POSES,
    weld_reading,
)
from graspscape.workers.sim.evaluate import Evaluator, default_cache_dir
from graspscape.workers.sim.objects import prepare_object
from scipy.stats import spearmanr

try:
    from benchmarks._results import write_results
except ModuleNotFoundError:
    from _results import write_results

POSES = {
    "sphere": [Pose(theta=t, phi=f, r=0.02) for t in (0.0, 0.8, 1.57, 2.3, 3.1)
               for f in (0.0, 2.0)],
    "mug": [Pose(theta=t, phi=f, r=0.02, roll=math.pi / 2) for t in (1.2, 1.57, 2.0)
            for f in (0.0, 1.5, 3.14, 4.7)],
}


def mu_values(metric: MetricSettings, length_factor: float = 1.0,
              world_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> list[float]:
    values = []
    for name, poses in POSES.items():
        prepared = prepare_object(ObjectSpec(name=name), default_cache_dir() / "objects")
        if length_factor != 1.0:
            radius = math.sqrt(sum(prepared.inertia_diag) / 3 / prepared.mass_kg)
            metric = metric.model_copy(update={"characteristic_length": length_factor * radius})
        with Evaluator(prepared, load_gripper("robotiq_3f"), SimSettings(metric=metric),
                       work_dir=default_cache_dir(), world_offset=world_offset) as evaluator:
            values += [evaluator.evaluate(pose).mu_s for pose in poses]
    return values


def weld_figures() -> dict[str, float]:
    """The estimator's anchor: the lowest per-instant reading of a weld, per object, and the
    spread of a weld's μs over three places of the object in the world."""
    figures: dict[str, float] = {}
    lowest = 1.0
    for name, scale in CALIBRATION_OBJECTS:
        prepared = prepare_object(ObjectSpec(name=name, scale=scale),
                                  default_cache_dir() / "objects")
        with Evaluator(prepared, load_gripper("robotiq_3f"), work_dir=default_cache_dir(),
                       ) as evaluator:
            readings = [q for pose in CALIBRATION_POSES for q in weld_reading(evaluator, pose)]
        label = name if scale == 1.0 else f"{name}_x{scale:g}"
        figures[f"weld_lowest_instant_quality.{label}"] = min(readings)
        lowest = min(lowest, min(readings))
    figures["weld_lowest_instant_quality"] = lowest
    prepared = prepare_object(ObjectSpec(name="mug"), default_cache_dir() / "objects")
    spread = 0.0
    for pose in CALIBRATION_POSES[1:]:
        values = []
        for offset in [(0.0, 0.0, 0.0), (0.5, -0.3, 0.2), (10.0, 10.0, 1.0)]:
            with Evaluator(prepared, load_gripper("robotiq_3f"), work_dir=default_cache_dir(),
                           world_offset=offset) as evaluator:
                values.append(min(weld_reading(evaluator, pose)))
        spread = max(spread, max(values) - min(values))
    figures["weld_mu_s_spread_over_world_offsets_mug"] = spread
    return figures


def halved(metric: MetricSettings) -> dict[str, MetricSettings]:
    """The metric settings with instants, window or probe size (linear and angular) halved;
    the characteristic length is halved by the caller, who knows the object's."""
    return {
        "instants": metric.model_copy(update={"instants": max(1, metric.instants // 2)}),
        "window": metric.model_copy(update={"window_steps": max(1, metric.window_steps // 2)}),
        "perturbation": metric.model_copy(update={
            "perturbation_m_s2": metric.perturbation_m_s2 / 2,
            "angular_perturbation_rad_s2": metric.angular_perturbation_rad_s2 / 2}),
    }


def main() -> None:
    base = MetricSettings()
    variants = halved(base)
    reference = np.array(mu_values(base))
    held = reference > 0
    figures: dict[str, float] = {"grasps": float(len(reference)),
                                 "held_grasps": float(held.sum()),
                                 "mean_mu_s_default": float(reference[held].mean()),
                                 **weld_figures()}
    variants_values = {name: mu_values(metric) for name, metric in variants.items()}
    variants_values["length"] = mu_values(base, length_factor=0.5)  # half the radius of gyration
    variants_values["moved_1um"] = mu_values(base, world_offset=(1e-6, 0.0, 0.0))
    variants_values["moved_0p5m"] = mu_values(base, world_offset=(0.5, -0.3, 0.2))
    variants_values["moved_10m"] = mu_values(base, world_offset=(10.0, 10.0, 1.0))
    for name, values in variants_values.items():
        values = np.array(values)
        label = name if name.startswith("moved") else f"halved_{name}"
        if name.startswith("moved"):
            figures[f"held_share_changed_{label}"] = float(np.mean((values > 0) != held))
        figures[f"mean_abs_mu_s_change_{label}"] = float(np.abs(values - reference)[held].mean())
        figures[f"rank_correlation_{label}"] = float(
            spearmanr(values[held], reference[held]).statistic)
    write_results("metric_stability", figures)


if __name__ == "__main__":
    main()
