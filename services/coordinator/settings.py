"""Coordinator settings: defaults < configs/coordinator.toml < GRASPSCAPE_* env vars < arguments.

Four sections, the same in the TOML file (`[api]`, `[queue]`, `[database]`, `[zenoh]`) and in
the environment (`GRASPSCAPE_<SECTION>__<KEY>`, e.g. GRASPSCAPE_API__TOKEN); the flat names of
before (GRASPSCAPE_API_TOKEN, a top-level `port`) are refused with the new name.

One cached object (`get_settings`) serves the process; tests and the CLI build their own
`Settings(...)` and hand it to `create_app`, so nothing global leaks between them. Secrets
(the API token, a database password inside the URL) come from the environment, never the
config file in the repository.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, SecretStr, field_validator, model_validator
from pydantic_settings import (
    BaseSettings,
    PydanticBaseSettingsSource,
    SettingsConfigDict,
    TomlConfigSettingsSource,
)

CONFIG_ENV = "GRASPSCAPE_CONFIG"
DEFAULT_CONFIG = Path("configs/coordinator.toml")


class ZenohSettings(BaseModel):
    """Dispatch over zenoh (`[zenoh]` in the TOML, GRASPSCAPE_ZENOH__<KEY> in the env)."""

    model_config = ConfigDict(extra="forbid")

    # Off for a bare create_app (tests, tools) so that it opens no network port; `graspscape
    # serve` and `explore` switch it on unless told --no-dispatch.
    enabled: bool = Field(default=False, description="serve workers over zenoh")
    mode: Literal["peer", "client"] = Field(
        default="peer", description="peer: embedded (listens); client: through a router only"
    )
    listen: list[str] = Field(
        default=["tcp/127.0.0.1:7447"],
        description="endpoints the embedded peer listens on; tcp/0.0.0.0:7447 for other hosts",
    )
    connect: list[str] = Field(
        default=[], description="zenoh router endpoints to connect to (multi-host deployment)"
    )
    handler_threads: int = Field(
        default=4, ge=1, le=64, description="threads storing result batches (ingest)"
    )
    lease_threads: int = Field(
        default=2, ge=1, le=64,
        description="threads serving lease and object queries, apart from ingest so that a "
        "lease never waits behind a batch's commit",
    )
    max_tiles_per_request: int = Field(default=8, ge=1, le=64)
    orphan_grace_s: float = Field(
        default=10.0,
        ge=0.0,
        description="after start, leases of workers not alive by then go back to the queue",
    )
    # Access control (zenoh usrpwd, docs/design/protocol.md "Access control"). The password comes
    # from the environment (GRASPSCAPE_ZENOH__PASSWORD), never the config file.
    user: str = Field(
        default="graspscape", pattern=r"^[^:\s]{1,64}$",
        description="user name of `password`: presented to routers in `connect`, and the one "
        "workers log in with when no users_file is given",
    )
    password: SecretStr | None = Field(
        default=None,
        description="when set, the embedded peer accepts only sessions logging in as `user` "
        "with it (or an entry of users_file), and this coordinator logs in with it",
    )
    users_file: Path | None = Field(
        default=None,
        description="zenoh dictionary file (`user:password` per line) of the workers the "
        "embedded peer accepts; unset with a password: `user` with `password` alone",
    )
    allow_unauthenticated: bool = Field(
        default=False,
        description="let the embedded peer listen beyond loopback without authentication "
        "(a trusted network, or zenoh TLS configured outside this file)",
    )

    @field_validator("password", "users_file", mode="before")
    @classmethod
    def _empty_is_unset(cls, value: object) -> object:
        # `GRASPSCAPE_ZENOH__PASSWORD=` (compose passes unset variables so) means no password.
        return None if value == "" else value

    @property
    def authenticates(self) -> bool:
        """Whether the embedded peer checks who connects (a password or a users file)."""
        return self.password is not None or self.users_file is not None

    def listen_refusal(self) -> str | None:
        """Why this peer must not listen as configured, or None: listening beyond loopback
        needs authentication unless `allow_unauthenticated` says otherwise."""
        if self.mode != "peer" or self.authenticates or self.allow_unauthenticated:
            return None
        from graspscape.shared.wire.session import is_local_endpoint

        exposed = [endpoint for endpoint in self.listen if not is_local_endpoint(endpoint)]
        if not exposed:
            return None
        return (
            f"zenoh would listen on {', '.join(exposed)}, beyond this host, without "
            "authentication: set GRASPSCAPE_ZENOH__PASSWORD (workers then log in with "
            "GRASPSCAPE_ZENOH__USER/__PASSWORD or --zenoh-user/--zenoh-password-file) or "
            "users_file, or accept any worker that reaches the port with "
            "allow_unauthenticated (--zenoh-allow-unauthenticated)"
        )

    @model_validator(mode="after")
    def _listen_safely(self) -> ZenohSettings:
        if self.enabled and (refusal := self.listen_refusal()) is not None:
            raise ValueError(refusal)
        return self


class ApiSettings(BaseModel):
    """The REST API (`[api]` in the TOML, GRASPSCAPE_API__<KEY> in the env)."""

    model_config = ConfigDict(extra="forbid")

    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=1, le=65535)
    token: SecretStr | None = Field(
        default=None, description="when set, mutating routes need 'Authorization: Bearer <it>'"
    )
    max_upload_bytes: int = Field(default=50 * 1024 * 1024, ge=1024)
    shared_objects_dir: Path | None = Field(
        default=None, description="folder of meshes that POST /objects may name as 'shared:<file>'"
    )

    @field_validator("token", "shared_objects_dir", mode="before")
    @classmethod
    def _empty_is_unset(cls, value: object) -> object:
        # `GRASPSCAPE_API__TOKEN=` (as compose passes an unset variable) means no token, not
        # the empty token.
        return None if value == "" else value


class QueueSettings(BaseModel):
    """Tiles, leases and limits (`[queue]`, GRASPSCAPE_QUEUE__<KEY>)."""

    model_config = ConfigDict(extra="forbid")

    lease_seconds: float = Field(default=300.0, gt=0, description="how long a tile lease lasts")
    max_attempts: int = Field(default=3, ge=1, description="leases of a tile before it fails")
    requeue_interval_s: float = Field(default=10.0, gt=0, description="expired-lease sweep period")
    tile_target_poses: int = Field(default=100, ge=1, le=10_000, description="poses per tile")
    max_poses_per_exploration: int = Field(default=5_000_000, ge=1)
    throughput_window_s: float = Field(default=60.0, gt=0, description="window of poses/s")


class DatabaseSettings(BaseModel):
    """Where the store lives (`[database]`, GRASPSCAPE_DATABASE__<KEY>)."""

    model_config = ConfigDict(extra="forbid")

    url: str | None = Field(
        default=None,
        description="SQLAlchemy URL; default: SQLite file coordinator.db under data_dir",
    )
    data_dir: Path = Field(default=Path("data"), description="folder of the embedded database")

    @field_validator("url", mode="before")
    @classmethod
    def _empty_is_unset(cls, value: object) -> object:
        return None if value == "" else value

    @property
    def resolved_url(self) -> str:
        if self.url:
            return self.url
        return f"sqlite:///{(self.data_dir / 'coordinator.db').as_posix()}"


# The flat names before the settings were nested (issue #17): refused, naming the new place,
# rather than silently ignored (a token that is no longer read would leave the API open).
MOVED = {
    "data_dir": "database.data_dir",
    "database_url": "database.url",
    "host": "api.host",
    "port": "api.port",
    "api_token": "api.token",
    "max_upload_bytes": "api.max_upload_bytes",
    "shared_objects_dir": "api.shared_objects_dir",
    **{key: f"queue.{key}" for key in QueueSettings.model_fields},
}


def _env_name(dotted: str) -> str:
    return "GRASPSCAPE_" + dotted.replace(".", "__").upper()


class Settings(BaseSettings):
    model_config = SettingsConfigDict(
        env_prefix="GRASPSCAPE_", env_nested_delimiter="__", extra="ignore"
    )

    api: ApiSettings = Field(default_factory=ApiSettings)
    queue: QueueSettings = Field(default_factory=QueueSettings)
    database: DatabaseSettings = Field(default_factory=DatabaseSettings)
    zenoh: ZenohSettings = Field(default_factory=ZenohSettings)

    @model_validator(mode="before")
    @classmethod
    def _refuse_flat_names(cls, data: object) -> object:
        old = [key for key in MOVED if os.environ.get(_env_name(key)) is not None]
        messages = [f"{_env_name(key)} is no longer read: set {_env_name(MOVED[key])}"
                    for key in old]
        if isinstance(data, dict):
            messages += [f"'{key}' is no longer read: set '{MOVED[key]}' ([{section}] {name} "
                         "in the config file)"
                         for key in data if key in MOVED
                         for section, name in [MOVED[key].split(".")]]
        if messages:
            raise ValueError("; ".join(messages))
        return data

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        toml_file = Path(os.environ.get(CONFIG_ENV, DEFAULT_CONFIG))
        return (
            init_settings,
            env_settings,
            TomlConfigSettingsSource(settings_cls, toml_file=toml_file),
        )


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    return Settings()
