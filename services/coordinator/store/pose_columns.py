"""The pose row's measured columns, defined once: each quality a worker reports beside μs
(the static grasp metrics of `PoseResult`, the margins and tests of its `RobustnessReport`).

Everything that spells a pose row out reads this tuple: the table's columns
(store/models.py), the ingest's values and statement (store/pose_rows.py), the shortcuts'
copies (exploration/planning.py), the API's pose (`PoseOut`, exploration/schemas.py), the
pose exports (CSV and Parquet, manifolds/export.py), the dataset exports' qualities
(datasets/rows.py) and `graspscape explore`'s CSV. A new quality is a line here, its field
on `PoseResult` (or `RobustnessReport`), and a migration adding the nullable column.

Each is a nullable float: NULL where the worker did not compute it (not chosen in the
exploration's settings, or the pose was not held).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class MetricColumn:
    """A measured quality: the poses' column, `PoseResult`'s field and `PoseOut`'s field of
    this name."""

    name: str
    description: str  # the API's words for it
    # False: `PoseResult.<name>`; True: `PoseResult.robustness.<name>` (the robustness report:
    # a batch without any report leaves these columns out of its statement, NULL)
    report: bool = False


METRIC_COLUMNS = (
    MetricColumn("mu_g", "grasp-matrix metric μg"),
    MetricColumn("mu_f", "Ferrari–Canny ε (μf)"),
    MetricColumn("mu_m", "perturbation resistance μm, in object weights"),
    MetricColumn("torque_margin_nm", "least closing effort at which the grasp still holds, N·m",
                 report=True),
    MetricColumn("torque_margin_ratio", "1 − torque_margin_nm / the closing effort used",
                 report=True),
    MetricColumn("friction_margin", "least object friction coefficient that still holds",
                 report=True),
    MetricColumn("gravity_test_share", "share of the 6 gravity directions passed", report=True),
    MetricColumn("force_test_share", "share of the 6 external force directions passed",
                 report=True),
    MetricColumn("tug_force_n", "pull along the approach axis at which the object slips, N",
                 report=True),
    MetricColumn("shake_survival_s", "time into the shake at which the object falls off, s",
                 report=True),
)

# By name, in the row's order: the static metrics, then the robustness report's.
GRASP_METRIC_COLUMNS = tuple(c.name for c in METRIC_COLUMNS if not c.report)
ROBUSTNESS_COLUMNS = tuple(c.name for c in METRIC_COLUMNS if c.report)
POSE_METRIC_COLUMNS = GRASP_METRIC_COLUMNS + ROBUSTNESS_COLUMNS
