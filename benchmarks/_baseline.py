"""A/B benchmarks of the running map's code: the manifolds and exploration packages of an
older commit, swapped in for a run of their own (`--baseline REF` of bench_ingest and
bench_incremental_manifolds).

The swap happens when this module is imported, so a benchmark imports it before any module of
those packages; the rest of the tree (store, scheduler) stays today's, so a difference is the
packages' alone."""

from __future__ import annotations

import importlib
import os
import subprocess
from pathlib import Path

PACKAGES_AT = "GRASPSCAPE_BENCH_PACKAGES"  # a baseline run: the folder holding the packages
# under services/coordinator; mapspace only where the commit has it (it holds the lattice's
# Point and the stored pose since it was made; before, exploration and manifolds did)
BASELINE_PACKAGES = ("manifolds", "exploration", "mapspace")
REPO = Path(__file__).resolve().parents[1]

if os.environ.get(PACKAGES_AT):
    for _name in BASELINE_PACKAGES:
        if not os.path.isdir(os.path.join(os.environ[PACKAGES_AT], "services/coordinator",
                                          _name)):
            continue
        importlib.import_module(f"graspscape.services.coordinator.{_name}").__path__[:] = [
            os.path.join(os.environ[PACKAGES_AT], "services/coordinator", _name)]


def extract_packages(ref: str, folder: str) -> None:
    """The packages as they were at git `ref`, written under `folder` (a PACKAGES_AT value)."""
    present = [f"services/coordinator/{name}" for name in BASELINE_PACKAGES
               if subprocess.run(["git", "cat-file", "-e", f"{ref}:services/coordinator/{name}"],
                                 cwd=REPO, capture_output=True).returncode == 0]
    archive = subprocess.run(["git", "archive", ref, *present], cwd=REPO, check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", folder], input=archive, check=True)
