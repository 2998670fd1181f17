"""`graspscape submit|status|best|export --url`: the client's commands against a live
coordinator, on both databases."""

from __future__ import annotations

import json
import threading

import trimesh
from graspscape.services.local.cli import main

from tests.services.client.test_client import _work


def test_submit_status_best_export(live_url, sessions, tmp_path, capsys) -> None:
    grid = ["--dtheta", "40", "--r-min", "0", "--r-max", "0.01", "--levels", "0"]
    assert main(["submit", "sphere", *grid, "--url", live_url]) == 0
    eid = capsys.readouterr().out.strip()
    assert eid.isdigit()
    worker = threading.Thread(target=_work, args=(sessions,))
    worker.start()
    worker.join()
    assert main(["status", eid, "--url", live_url]) == 0
    assert capsys.readouterr().out.startswith(f"exploration {eid}: done, ")
    assert main(["best", eid, "--limit", "2", "--url", live_url]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("best by ") and len(lines) == 3
    out = tmp_path / "grasps.json"
    assert main(["export", eid, "--what", "graspgen.json", "-o", str(out), "--url",
                 live_url]) == 0
    named = tmp_path / json.loads(out.read_text())["object"]["file"]
    assert len(trimesh.load(named, force="mesh").faces) > 0


def test_submit_states_the_draws_engines(live_url, capsys) -> None:
    """submit --draw-engines makes the spec explore's would: the engines in its uncertainty."""
    grid = ["--dtheta", "40", "--r-min", "0", "--r-max", "0.01", "--levels", "0"]
    assert main(["submit", "sphere", *grid, "--uncertainty", "field", "--draw-engines",
                 "pybullet,mujoco", "--url", live_url]) == 0
    eid = capsys.readouterr().out.strip()
    assert main(["status", eid, "--json", "--url", live_url]) == 0
    uncertainty = json.loads(capsys.readouterr().out)["spec"]["uncertainty"]
    assert uncertainty["engines"] == ["pybullet", "mujoco"]
    assert uncertainty["preset"] == "field" and uncertainty["position_mm"] == 5.0


def test_submit_refusal_is_one_line(live_url, capsys) -> None:
    assert main(["submit", "no-such-object", "--url", live_url]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("graspscape submit: error: 422 from ") and "\n" not in err


def test_the_commands_offer_what_the_client_exports() -> None:
    from graspscape.services.client import EXPORTS
    from graspscape.services.client.cli import EXPORTS as OFFERED

    assert OFFERED == EXPORTS
