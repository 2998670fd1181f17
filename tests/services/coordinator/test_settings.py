"""Settings sources and their order: defaults < config file < GRASPSCAPE_* env < arguments,
in the same nested shape everywhere ([api], [queue], [database], [zenoh])."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
from graspscape.services.coordinator.settings import MOVED, Settings, get_settings


@pytest.fixture(autouse=True)
def _no_flat_env(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("GRASPSCAPE_API__TOKEN", "GRASPSCAPE_DATABASE__URL"):
        monkeypatch.delenv(name, raising=False)


def test_config_file_then_env_then_arguments(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    config = tmp_path / "coordinator.toml"
    config.write_text("[api]\nport = 9001\n[queue]\nlease_seconds = 42.0\nmax_attempts = 7\n")
    monkeypatch.setenv("GRASPSCAPE_CONFIG", str(config))
    monkeypatch.setenv("GRASPSCAPE_QUEUE__MAX_ATTEMPTS", "5")
    settings = Settings(queue={"lease_seconds": 9.0})
    assert (settings.api.port, settings.queue.max_attempts, settings.queue.lease_seconds) == (
        9001, 5, 9.0)
    assert settings.api.token is None


def test_default_database_is_sqlite_under_the_data_dir(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("GRASPSCAPE_CONFIG", str(tmp_path / "absent.toml"))
    settings = Settings(database={"data_dir": tmp_path})
    assert settings.database.resolved_url == f"sqlite:///{tmp_path}/coordinator.db"


def test_empty_env_token_means_no_token(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("GRASPSCAPE_API__TOKEN", "")
    assert Settings().api.token is None
    monkeypatch.setenv("GRASPSCAPE_API__TOKEN", "t0k")
    token = Settings().api.token
    assert token is not None and token.get_secret_value() == "t0k"
    assert "t0k" not in repr(Settings())


def test_invalid_values_are_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("GRASPSCAPE_API__PORT", "70000")
    with pytest.raises(ValueError, match="port"):
        Settings()


@pytest.mark.parametrize("old", sorted(MOVED))
def test_the_flat_names_of_before_are_refused_naming_the_new_one(
    old: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    new_env = "GRASPSCAPE_" + MOVED[old].replace(".", "__").upper()
    monkeypatch.setenv(f"GRASPSCAPE_{old.upper()}", "1")
    with pytest.raises(ValueError, match=new_env):
        Settings()
    monkeypatch.delenv(f"GRASPSCAPE_{old.upper()}")
    config = tmp_path / "old.toml"
    config.write_text(f"{old} = 1\n")
    monkeypatch.setenv("GRASPSCAPE_CONFIG", str(config))
    with pytest.raises(ValueError, match=MOVED[old].replace(".", r"\.")):
        Settings()


def test_get_settings_is_cached() -> None:
    assert get_settings() is get_settings()


def test_repository_config_file_is_valid(monkeypatch: pytest.MonkeyPatch) -> None:
    repo_config = Path(__file__).resolve().parents[3] / "configs" / "coordinator.toml"
    sections = tomllib.loads(repo_config.read_text())
    assert set(sections) <= set(Settings.model_fields)
    assert "token" not in sections.get("api", {})
    monkeypatch.setenv("GRASPSCAPE_CONFIG", str(repo_config))
    assert Settings().model_dump() == Settings(**sections).model_dump()
