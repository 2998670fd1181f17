"""Settings of one worker (all its processes): where the coordinator is, how many processes,
where objects are cached, and how patiently to retry."""

from __future__ import annotations

import os
import re
import secrets
import socket
from pathlib import Path

from graspscape.shared.specs.sim import EngineName
from graspscape.workers.sim.engine import available_engines
from pydantic import BaseModel, ConfigDict, Field, SecretStr, SerializationInfo, field_serializer


def default_procs() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def default_name() -> str:
    host = re.sub(r"[^A-Za-z0-9_.-]", "-", socket.gethostname())[:60] or "worker"
    if not host[0].isalnum():
        host = "w" + host
    return f"{host}-{secrets.token_hex(3)}"


class WorkerConfig(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    connect: list[str] = Field(default=["tcp/127.0.0.1:7447"], min_length=1)
    procs: int = Field(default_factory=default_procs, ge=1, le=512)
    name: str = Field(default_factory=default_name, pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,80}$")
    cache_dir: Path | None = Field(default=None, description="default: GRASPSCAPE_CACHE_DIR")
    # No physics: answer every pose at once with a fixed result. Measures the coordinator's
    # dispatch + ingest ceiling through the real protocol; never for real explorations.
    instant: bool = False
    # With `instant`: seconds each made-up pose takes (a sleep, no CPU), so fault tests can
    # cut a link or kill a process in the middle of a tile without paying for physics.
    instant_pose_s: float = Field(default=0.0, ge=0, le=60)
    tiles_per_request: int = Field(default=1, ge=1, le=64)
    # The physics engines this worker runs and advertises in its lease requests (it is leased
    # tiles of those only): by default every one installed here.
    engines: tuple[EngineName, ...] = Field(default_factory=available_engines, min_length=1)
    query_timeout_s: float = Field(default=10.0, gt=0)
    backoff_min_s: float = Field(default=0.2, gt=0)
    backoff_max_s: float = Field(default=5.0, gt=0)
    # After SIGTERM, how long a process keeps trying to deliver its last batch before it
    # exits anyway (its tile then comes back by liveliness or lease expiry).
    shutdown_grace_s: float = Field(default=30.0, ge=0)
    # A process that crashed (not one that was told to stop) is started again.
    restart_crashed: bool = True
    # zenoh usrpwd login, where the coordinator or router asks for one (docs/design/protocol.md,
    # "Access control"); no password: no login.
    zenoh_user: str = Field(default="graspscape", pattern=r"^[^:\s]{1,64}$")
    zenoh_password: SecretStr | None = None

    @field_serializer("zenoh_password", when_used="json")
    def _password_for_processes(self, value: SecretStr | None,
                                info: SerializationInfo) -> str | None:
        """Written out only for the supervisor's own processes (model_dump_json with
        context {"secrets": True}); anywhere else it stays masked."""
        if value is None:
            return None
        if info.context and info.context.get("secrets"):
            return value.get_secret_value()
        return str(value)

    def zenoh_login(self) -> dict[str, str]:
        """The `user` and `password` arguments of shared.wire.session.zenoh_config."""
        if self.zenoh_password is None:
            return {}
        return {"user": self.zenoh_user, "password": self.zenoh_password.get_secret_value()}
