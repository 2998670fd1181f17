"""What the command line refuses, in one line each: a model's bound (`eval-pose --mass 0`),
`serve`'s refusal to listen beyond loopback without a login, a number that underflows to
zero, a URDF whose mesh lies outside its folder, a degenerate mesh named as such."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import trimesh
from graspscape.services.local.cli import main
from graspscape.workers.sim.objects.catalog import ycb_root
from graspscape.workers.sim.objects.urdf import read_urdf

POSE = ["--theta", "90", "--phi", "0"]


def _one_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if not line.startswith("warning:")]
    assert len(lines) == 1, err
    return lines[0]


def test_a_bound_of_the_object_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["eval-pose", "sphere", "--mass", "0", *POSE])
    assert exited.value.code == 2
    # argparse's usage, then the refusal in one line naming the flag, the range and the unit.
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == "graspscape eval-pose: error: argument --mass: 0 is not in (0, 50] kg"
    assert not any("validation error" in line for line in err)


def test_serve_s_login_refusal_is_one_line(
    sqlite_url: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    for name in ("PASSWORD", "USERS_FILE", "ALLOW_UNAUTHENTICATED"):
        monkeypatch.delenv(f"GRASPSCAPE_ZENOH__{name}", raising=False)
    assert main(["serve", "--database-url", sqlite_url, "--no-migrate",
                 "--zenoh-listen", "tcp/0.0.0.0:7447"]) == 1
    line = _one_line(capsys)
    assert line.startswith("graspscape serve: error: zenoh: zenoh would listen on "
                           "tcp/0.0.0.0:7447, beyond this host, without authentication")
    assert "validation error" not in line and "Value error" not in line


@pytest.mark.parametrize("command", ["eval-pose", "explore"])
def test_a_property_that_underflows_to_zero_is_refused(
    command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exited:
        main([command, "--object" if command == "eval-pose" else "sphere", *(
            ["sphere", *POSE] if command == "eval-pose" else []), "--friction", "1e-400"])
    assert exited.value.code == 2
    assert "argument --friction: '1e-400': Input is too small for a float" in (
        capsys.readouterr().err)


@pytest.mark.skipif(not ycb_root().is_dir(), reason="YCB folder not present")
def test_a_urdf_whose_mesh_lies_outside_its_folder_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = ycb_root() / "YcbBanana"
    outside = tmp_path / "elsewhere.obj"
    shutil.copy(source / "collision_vhacd.obj", outside)
    folder = tmp_path / "banana"
    folder.mkdir()
    urdf = (source / "model.urdf").read_text().replace(
        'filename="collision_vhacd.obj"', 'filename="../elsewhere.obj"')
    (folder / "model.urdf").write_text(urdf)
    assert main(["eval-pose", "--object", str(folder / "model.urdf"), *POSE]) == 1
    line = _one_line(capsys)
    assert "points outside its folder" in line and "elsewhere.obj" in line
    # The same file beside it is read.
    shutil.copy(outside, folder / "elsewhere.obj")
    (folder / "model.urdf").write_text(urdf.replace("../elsewhere.obj", "elsewhere.obj"))
    read = read_urdf(folder / "model.urdf", "banana")
    assert read.collision[0] == folder / "elsewhere.obj"


def test_a_degenerate_mesh_is_named_so_not_measured(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Two metres of triangles whose corners lie on one line: no surface at all.
    line_mesh = trimesh.Trimesh(vertices=[[0, 0, 0], [1, 0, 0], [2, 0, 0], [0.5, 0, 0]],
                                faces=[[0, 1, 2], [0, 1, 3], [1, 2, 3], [0, 2, 3]],
                                process=False)
    path = tmp_path / "line.obj"
    path.write_text(line_mesh.export(file_type="obj"))
    assert main(["eval-pose", "--object", str(path), "--mass", "0.1", *POSE]) == 1
    line = _one_line(capsys)
    assert "mesh is degenerate" in line and "too large" not in line
