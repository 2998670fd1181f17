"""`map show` and `map export` read an existing database only: without one they are refused
with the commands that make one, and create no folder or file."""

from __future__ import annotations

from pathlib import Path

import pytest
from graspscape.services.local.cli import main


@pytest.mark.parametrize("argv", [
    ["map", "export", "1", "-o", "poses.csv"],
    ["map", "show", "1"],
    ["map", "export", "1", "--what", "graspgen.json", "-o", "g.json", "--data-dir", "elsewhere"],
])
def test_a_missing_database_is_refused_and_nothing_created(argv, tmp_path: Path, monkeypatch,
                                                            capsys) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("GRASPSCAPE_DATABASE__URL", raising=False)
    monkeypatch.delenv("GRASPSCAPE_DATABASE__DATA_DIR", raising=False)
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("graspscape map: error: no database at ") and "\n" not in err
    assert "graspscape explore OBJECT --data-dir" in err
    assert list(tmp_path.iterdir()) == []


def test_a_database_without_the_schema_is_refused(tmp_path: Path, capsys) -> None:
    import sqlite3

    sqlite3.connect(tmp_path / "coordinator.db").close()  # a file, but no tables
    assert main(["map", "show", "1", "--data-dir", str(tmp_path)]) == 1
    assert "has no graspscape schema" in capsys.readouterr().err
