"""Settings sources and their order: defaults < config file < GRASPSCAPE_* env < arguments."""

from __future__ import annotations

from pathlib import Path

import pytest
from graspscape.services.coordinator.settings import Settings, get_settings


def test_config_file_then_env_then_arguments(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    config = tmp_path / "coordinator.toml"
    config.write_text("port = 9001\nlease_seconds = 42.0\nmax_attempts = 7\n")
    monkeypatch.setenv("GRASPSCAPE_CONFIG", str(config))
    monkeypatch.setenv("GRASPSCAPE_MAX_ATTEMPTS", "5")
    monkeypatch.delenv("GRASPSCAPE_API_TOKEN", raising=False)
    settings = Settings(lease_seconds=9.0)
    assert (settings.port, settings.max_attempts, settings.lease_seconds) == (9001, 5, 9.0)
    assert settings.api_token is None


def test_default_database_is_sqlite_under_the_data_dir(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("GRASPSCAPE_CONFIG", str(tmp_path / "absent.toml"))
    monkeypatch.delenv("GRASPSCAPE_DATABASE_URL", raising=False)
    settings = Settings(data_dir=tmp_path)
    assert settings.resolved_database_url == f"sqlite:///{tmp_path}/coordinator.db"


def test_empty_env_token_means_no_token(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("GRASPSCAPE_API_TOKEN", "")
    assert Settings().api_token is None
    monkeypatch.setenv("GRASPSCAPE_API_TOKEN", "t0k")
    token = Settings().api_token
    assert token is not None and token.get_secret_value() == "t0k"
    assert "t0k" not in repr(Settings())


def test_invalid_values_are_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("GRASPSCAPE_PORT", "70000")
    with pytest.raises(ValueError, match="port"):
        Settings()


def test_get_settings_is_cached() -> None:
    assert get_settings() is get_settings()


def test_repository_config_file_is_valid() -> None:
    repo_config = Path(__file__).resolve().parents[3] / "configs" / "coordinator.toml"
    import tomllib

    keys = set(tomllib.loads(repo_config.read_text()))
    assert keys <= set(Settings.model_fields)
    assert "api_token" not in keys
