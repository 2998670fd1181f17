"""Access control of the zenoh port (issue 19, finding 2: "the zenoh port has no
authentication"): zenoh's usrpwd login between workers and the coordinator's embedded peer,
over loopback with real sessions, and the refusal to listen beyond loopback without it.

The store does not take part in a login, so the sessions run against SQLite only."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh
from graspscape.services.coordinator.dispatch.service import Dispatcher
from graspscape.services.coordinator.settings import Settings, ZenohSettings
from graspscape.shared.wire.messages import TileLease
from graspscape.shared.wire.session import is_local_endpoint, write_users_file
from graspscape.workers.runtime.config import WorkerConfig
from graspscape.workers.runtime.process import Stopped, WorkerProcess
from graspscape.workers.runtime.session import session_config
from prometheus_client import CollectorRegistry
from sqlalchemy.orm import Session, sessionmaker

from tests.services.coordinator.dispatch.support import free_port, submit


@pytest.mark.parametrize(
    ("endpoint", "local"),
    [
        ("tcp/127.0.0.1:7447", True),
        ("tcp/127.3.4.5:7447", True),
        ("tcp/[::1]:7447", True),
        ("tcp/localhost:7447", True),
        ("udp/127.0.0.1:7447#iface=lo", True),
        ("unixsock-stream//tmp/graspscape.sock", True),
        ("tcp/0.0.0.0:7447", False),
        ("tcp/[::]:7447", False),
        ("tcp/10.0.0.5:7447", False),
        ("tcp/coordinator.example:7447", False),
        ("tls/127.0.0.1.example:7447", False),
        ("tcp/127.0.0.1", False),  # no port: not an address this can vouch for
    ],
)
def test_which_endpoints_stay_on_this_host(endpoint: str, local: bool) -> None:
    assert is_local_endpoint(endpoint) is local


def test_listening_beyond_loopback_needs_a_login_or_an_explicit_flag(tmp_path: Path) -> None:
    exposed = ["tcp/127.0.0.1:7447", "tcp/0.0.0.0:7447"]
    with pytest.raises(ValueError, match=r"listen on tcp/0\.0\.0\.0:7447, beyond this host, "
                                         "without authentication"):
        ZenohSettings(enabled=True, listen=exposed)
    # Loopback, a client of routers, dispatch off: nothing to refuse.
    ZenohSettings(enabled=True)
    ZenohSettings(enabled=True, mode="client", listen=exposed, connect=["tcp/router:7447"])
    ZenohSettings(enabled=False, listen=exposed)
    # A login, or the explicit flag.
    assert ZenohSettings(enabled=True, listen=exposed, password="pw").authenticates
    assert ZenohSettings(enabled=True, listen=exposed, users_file=tmp_path / "u").authenticates
    assert not ZenohSettings(enabled=True, listen=exposed,
                             allow_unauthenticated=True).authenticates
    # `GRASPSCAPE_ZENOH__PASSWORD=` (compose's unset variable) is no password.
    assert ZenohSettings(password="").password is None


def test_the_dispatcher_will_not_open_an_unauthenticated_port_beyond_loopback(
    sqlite_url: str, sqlite_sessions: sessionmaker[Session]
) -> None:
    # Settings made with dispatch off pass validation; the dispatcher checks again itself.
    zs = ZenohSettings(enabled=False, listen=[f"tcp/0.0.0.0:{free_port()}"])
    dispatcher = Dispatcher(Settings(database={"url": sqlite_url}, zenoh=zs), sqlite_sessions,
                            CollectorRegistry())
    with pytest.raises(ValueError, match="without authentication"):
        dispatcher.start()
    assert not dispatcher.ready
    dispatcher.stop()


def test_serve_refuses_to_listen_beyond_loopback_without_a_login(
    sqlite_url: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import uvicorn
    from graspscape.services.local.cli import main

    served: list[object] = []
    monkeypatch.setattr(uvicorn, "run", lambda app, **kwargs: served.append(app))
    monkeypatch.delenv("GRASPSCAPE_ZENOH__PASSWORD", raising=False)
    monkeypatch.delenv("GRASPSCAPE_ZENOH__USERS_FILE", raising=False)
    monkeypatch.delenv("GRASPSCAPE_ZENOH__ALLOW_UNAUTHENTICATED", raising=False)
    args = ["serve", "--database-url", sqlite_url, "--no-migrate",
            "--zenoh-listen", "tcp/0.0.0.0:7447"]
    assert main(args) == 1
    assert "without authentication" in capsys.readouterr().err and not served
    assert main([*args, "--zenoh-allow-unauthenticated"]) == 0 and len(served) == 1
    monkeypatch.setenv("GRASPSCAPE_ZENOH__PASSWORD", "pw")
    assert main(args) == 0 and len(served) == 2


@pytest.fixture
def guarded(sqlite_url: str, sqlite_sessions: sessionmaker[Session],
            tmp_path: Path) -> Iterator[tuple[Dispatcher, CollectorRegistry]]:
    """A dispatcher whose peer (on loopback) lets in `graspscape` with `s3cret`, and the
    users of a dictionary file: here only the first, the second is checked by its own test."""
    registry = CollectorRegistry()
    port = free_port()
    settings = Settings(database={"url": sqlite_url}, zenoh=ZenohSettings(
        enabled=True, listen=[f"tcp/127.0.0.1:{port}"], orphan_grace_s=3600,
        password="s3cret"))
    dispatcher = Dispatcher(settings, sqlite_sessions, registry)
    dispatcher.start()
    assert dispatcher.ready
    yield dispatcher, registry
    dispatcher.stop()


def worker(dispatcher: Dispatcher, **login: str) -> WorkerProcess:
    config = WorkerConfig(connect=dispatcher.zenoh_settings.listen,
                          procs=1, name="auth", instant=True,
                          query_timeout_s=5, backoff_min_s=0.2, backoff_max_s=0.5, **login)
    return WorkerProcess(config, 0)


def lease_queries(registry: CollectorRegistry) -> float:
    return registry.get_sample_value("graspscape_dispatch_queries_total",
                                     {"kind": "lease", "outcome": "ok"}) or 0.0


@pytest.mark.slow
def test_a_worker_with_the_right_login_gets_work_and_a_wrong_one_never_reaches_it(
    guarded: tuple[Dispatcher, CollectorRegistry], sqlite_sessions: sessionmaker[Session]
) -> None:
    dispatcher, registry = guarded
    submit(sqlite_sessions, tile_poses=3)
    # The worker's own session code (WorkerProcess._open, as `graspscape worker` runs it).
    right = worker(dispatcher, zenoh_password="s3cret")
    right.session = right._open()
    try:
        (tile,) = right._lease()
    finally:
        right.session.close()
    assert isinstance(tile, TileLease) and lease_queries(registry) == 1

    for login in ({"zenoh_password": "wrong"}, {"zenoh_user": "intruder",
                                                "zenoh_password": "s3cret"}, {}):
        refused = worker(dispatcher, **login)
        with pytest.raises(zenoh.ZError):
            zenoh.open(session_config(refused.config))
        # The process keeps trying (the coordinator may not be up yet) until it is stopped.
        stop = threading.Timer(2.5, refused.request_stop)
        stop.start()
        with pytest.raises(Stopped):
            refused._open()
        stop.join()
    assert lease_queries(registry) == 1  # no query of theirs ever arrived


@pytest.mark.slow  # seconds of physics or subprocess: the default run stays near 90 s
def test_a_users_file_admits_each_of_its_users(
    sqlite_url: str, sqlite_sessions: sessionmaker[Session], tmp_path: Path
) -> None:
    users = write_users_file(tmp_path / "users", {"hostA": "pwA", "hostB": "pwB"})
    assert users.stat().st_mode & 0o777 == 0o600
    settings = Settings(database={"url": sqlite_url}, zenoh=ZenohSettings(
        enabled=True, listen=[f"tcp/0.0.0.0:{free_port()}"], users_file=users,
        orphan_grace_s=3600))
    dispatcher = Dispatcher(settings, sqlite_sessions, CollectorRegistry())
    dispatcher.start()
    assert dispatcher.ready
    loopback = [dispatcher.zenoh_settings.listen[0].replace("0.0.0.0", "127.0.0.1")]
    try:
        submit(sqlite_sessions, tile_poses=3)
        for user, password in (("hostA", "pwA"), ("hostB", "pwB")):
            config = WorkerConfig(connect=loopback, procs=1, name=user, zenoh_user=user,
                                  zenoh_password=password)
            session = zenoh.open(session_config(config))
            session.close()
        with pytest.raises(zenoh.ZError):
            zenoh.open(session_config(WorkerConfig(connect=loopback, procs=1, name="c",
                                                   zenoh_user="hostA", zenoh_password="pwB")))
    finally:
        dispatcher.stop()


def test_the_worker_command_takes_its_login_from_a_file_or_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import graspscape.workers.runtime.supervisor as supervisor
    from graspscape.services.local.cli import main

    configs: list[WorkerConfig] = []
    monkeypatch.setattr(supervisor, "run_worker",
                        lambda config, log_level="info": configs.append(config) or 0)
    monkeypatch.setenv("GRASPSCAPE_ZENOH__USER", "hostA")
    monkeypatch.setenv("GRASPSCAPE_ZENOH__PASSWORD", "from-env")
    secret = tmp_path / "password"
    secret.write_text("from-file\n")
    assert main(["worker", "--procs", "1"]) == 0
    assert main(["worker", "--procs", "1", "--zenoh-user", "hostB",
                 "--zenoh-password-file", str(secret)]) == 0
    monkeypatch.setenv("GRASPSCAPE_ZENOH__PASSWORD", "")
    assert main(["worker", "--procs", "1"]) == 0
    assert [c.zenoh_login() for c in configs] == [
        {"user": "hostA", "password": "from-env"}, {"user": "hostB", "password": "from-file"},
        {}]
    # The supervisor hands the password to its processes, and only to them.
    spawned = configs[0].model_dump_json(context={"secrets": True})
    assert WorkerConfig.model_validate_json(spawned).zenoh_login()["password"] == "from-env"
    assert "from-env" not in configs[0].model_dump_json() + repr(configs[0])
