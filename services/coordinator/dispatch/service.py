"""The Dispatcher: one zenoh session in the coordinator, serving workers from the store.

Zenoh callbacks only enqueue (a full queue is answered "unavailable" at once); pools of
handler threads do the database work and reply inside the query's context (`with query`),
so the final reply goes out as soon as the answer is complete. Two pools, two queues: result
batches (ingest: a transaction that waits its turn at the exploration's row lock) and leases
with mesh and gripper fetches (one short transaction each), so a lease never queues behind a
batch's commit; leasing stays safe against the ingest threads and other coordinators by the
store's own means (SKIP LOCKED, lease epochs, lease-owner checks; each answer's store work is
dispatch/answers.py's). Nothing raised while serving a query escapes: bad input gets an
error reply, anything raised one as dispatch/refusals.py says, with one log line at most.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import shutil
import tempfile
import threading
from pathlib import Path
from typing import Any

import zenoh
from graspscape.services.coordinator.dispatch.alive import alive_workers
from graspscape.services.coordinator.dispatch.answers import (
    count_refusal,
    lease_for,
    report_batch,
)
from graspscape.services.coordinator.dispatch.catalog import WorkContexts, fetch_answer
from graspscape.services.coordinator.dispatch.counters import DispatchCounters
from graspscape.services.coordinator.dispatch.leases import lease_owners, requeue_lost
from graspscape.services.coordinator.dispatch.outage import StoreOutage
from graspscape.services.coordinator.dispatch.refusals import failed_reply
from graspscape.services.coordinator.dispatch.sessions import WorkerSessions
from graspscape.services.coordinator.errors import WorkerIdTaken
from graspscape.services.coordinator.settings import Settings
from graspscape.services.coordinator.state import current
from graspscape.shared.heap import freeze_startup_heap
from graspscape.shared.wire import keys
from graspscape.shared.wire.codec import batch_header, decode_as, encode, error
from graspscape.shared.wire.messages import (
    ErrorCode,
    ErrorReply,
    LeaseRequest,
    ResultBatch,
)
from graspscape.shared.wire.session import write_users_file, zenoh_config
from prometheus_client import CollectorRegistry
from sqlalchemy.orm import Session, sessionmaker

log = logging.getLogger("graspscape.dispatch")

_QUEUE_SIZE = 2048
_STOP = object()


class Dispatcher:
    def __init__(
        self,
        settings: Settings,
        sessions: sessionmaker[Session],
        registry: CollectorRegistry | None = None,
    ) -> None:
        self.settings = settings
        self.zenoh_settings = settings.zenoh
        self.sessions = sessions
        self.counters = DispatchCounters(registry)
        self.outage = StoreOutage()
        self.contexts = WorkContexts()
        self.worker_sessions = WorkerSessions()
        # kind -> its pool's queue: result batches apart from leases and fetches.
        ingest: queue.Queue[Any] = queue.Queue(maxsize=_QUEUE_SIZE)
        leases: queue.Queue[Any] = queue.Queue(maxsize=_QUEUE_SIZE)
        self._queues: dict[str, queue.Queue[Any]] = {
            "results": ingest, "lease": leases, "object": leases, "gripper": leases}
        self._pools: list[tuple[queue.Queue[Any], list[threading.Thread]]] = []
        self._lost_keys: queue.SimpleQueue[str | None] = queue.SimpleQueue()
        self._threads: list[threading.Thread] = []
        self._session: zenoh.Session | None = None
        self._declared: list[Any] = []
        self._stopping = threading.Event()
        # SQLite has one writer: threads contending for it sleep in its busy handler (up to
        # 100 ms a turn); taking turns here keeps writes back to back. PostgreSQL: concurrent.
        backend = sessions.kw["bind"].dialect.name if sessions.kw.get("bind") else ""
        self._store_turn = threading.Lock() if backend == "sqlite" else contextlib.nullcontext()
        self._users_dir: Path | None = None  # the dictionary made from user + password
        # Its threads are started through the coordinator's state (state.py), which joins
        # them at its close and runs them with itself current (the specs, the keeper).
        self._state = current()

    # -- lifecycle -----------------------------------------------------------------------

    @property
    def ready(self) -> bool:
        return self._session is not None

    def start(self) -> None:
        """Open the session and declare everything, or keep retrying in the background.

        A listen endpoint that is taken (another coordinator on this host) must not take the
        REST API down with it: the failure is logged and counted, and retried every few s.
        Listening beyond loopback without authentication is refused at once (ValueError),
        unless the settings allow it explicitly.
        """
        refusal = self.zenoh_settings.listen_refusal()
        if refusal is not None:
            raise ValueError(refusal)
        users_file = self.zenoh_settings.users_file
        if users_file is not None and not users_file.is_file():
            raise ValueError(f"zenoh users_file {users_file} is not a file")
        try:
            self._open()
        except Exception as exc:
            self.counters.errors.labels("session", "open").inc()
            log.error("zenoh session could not open (%s); retrying in the background", exc)
            retry = self._state.start_thread(self._retry_open, name="dispatch-open", daemon=True)
            self._threads.append(retry)

    def _retry_open(self) -> None:
        while not self._stopping.wait(5.0):
            try:
                self._open()
                return
            except Exception as exc:
                self.counters.errors.labels("session", "open").inc()
                log.error("zenoh session could not open (%s); retrying", exc)

    def _users_file(self, listen: list[str]) -> Path | None:
        """The logins the embedded peer admits: users_file, or one of user + password."""
        if not listen or not self.zenoh_settings.authenticates:
            return None
        if self.zenoh_settings.users_file is not None:
            return self.zenoh_settings.users_file
        assert self.zenoh_settings.password is not None
        if self._users_dir is None:
            self._users_dir = Path(tempfile.mkdtemp(prefix="graspscape-zenoh-"))
        login = self.zenoh_settings
        return write_users_file(self._users_dir / "users",
                                {login.user: login.password.get_secret_value()})

    def _open(self) -> None:
        # A client only connects (to routers); only the embedded peer listens.
        listen = self.zenoh_settings.listen if self.zenoh_settings.mode == "peer" else []
        secret = self.zenoh_settings.password
        password = secret.get_secret_value() if secret is not None else None
        # A client without its router fails after 5 s and is retried by start(); a peer
        # opens at once and keeps dialling its routers in the background.
        session = zenoh.open(
            zenoh_config(
                mode=self.zenoh_settings.mode,
                listen=listen,
                connect=self.zenoh_settings.connect,
                connect_timeout_ms=5000,
                exit_on_failure=self.zenoh_settings.mode == "client",
                user=self.zenoh_settings.user if password is not None else None,
                password=password,
                users_file=self._users_file(listen),
            )
        )
        self._session = session
        for name, work, count in (
            ("dispatch-ingest", self._queues["results"], self.zenoh_settings.handler_threads),
            ("dispatch-lease", self._queues["lease"], self.zenoh_settings.lease_threads),
        ):
            pool = [self._state.start_thread(self._serve, args=(work,), name=name, daemon=True)
                    for _ in range(count)]
            self._pools.append((work, pool))
        watcher = self._state.start_thread(self._watch_lost, name="dispatch-lost", daemon=True)
        self._threads.append(watcher)
        s = self._session
        self._declared = [
            s.declare_queryable(keys.LEASE_QUERYABLE, self._enqueue("lease")),
            s.declare_queryable(keys.RESULTS_QUERYABLE, self._enqueue("results")),
            s.declare_queryable(keys.OBJECT_QUERYABLE, self._enqueue("object")),
            s.declare_queryable(keys.GRIPPER_QUERYABLE, self._enqueue("gripper")),
            # history: tokens of workers that were there before this coordinator started.
            s.liveliness().declare_subscriber(keys.ALIVE_ALL, self._on_alive, history=True),
        ]
        sweeper = self._state.start_thread(self._orphan_sweep, name="dispatch-orphans",
                                           daemon=True)
        self._threads.append(sweeper)
        freeze_startup_heap()
        log.info(
            "dispatch up: zenoh %s, listen %s, connect %s, %s",
            self.zenoh_settings.mode,
            self.zenoh_settings.listen,
            self.zenoh_settings.connect,
            "workers log in (usrpwd)" if self.zenoh_settings.authenticates else "no authentication",
        )

    def stop(self) -> None:
        self._stopping.set()
        self._lost_keys.put(None)
        for entity in self._declared:
            try:
                entity.undeclare()
            except Exception:  # already gone with a closing session
                log.debug("undeclare failed", exc_info=True)
        for work, pool in self._pools:
            for _ in pool:
                try:
                    work.put(_STOP, timeout=1)
                except queue.Full:
                    break
        for thread in [*self._threads, *(t for _, pool in self._pools for t in pool)]:
            thread.join(timeout=5)
        self._threads, self._pools, self._declared = [], [], []
        if self._session is not None:
            self._session.close()
            self._session = None
        if self._users_dir is not None:
            shutil.rmtree(self._users_dir, ignore_errors=True)
            self._users_dir = None

    # -- callbacks: enqueue only -----------------------------------------------------------

    def _enqueue(self, kind: str):
        work = self._queues[kind]

        def callback(query: zenoh.Query) -> None:
            try:
                work.put_nowait((kind, query))
            except queue.Full:
                self.counters.errors.labels(kind, "busy").inc()
                with query:
                    query.reply_err(encode(error(ErrorCode.UNAVAILABLE, "coordinator busy")))
            except Exception:
                self.counters.errors.labels(kind, "callback").inc()
                log.exception("%s callback failed", kind)

        return callback

    def _on_alive(self, sample: zenoh.Sample) -> None:
        try:
            if sample.kind == zenoh.SampleKind.DELETE:
                self._lost_keys.put(str(sample.key_expr))  # unbounded: never blocks
        except Exception:
            self.counters.errors.labels("liveliness", "callback").inc()
            log.exception("liveliness callback failed")

    # -- handler threads -------------------------------------------------------------------

    def _serve(self, work: queue.Queue[Any]) -> None:
        while True:
            item = work.get()
            if item is _STOP:
                return
            kind, payload = item
            try:
                with payload:  # the final reply goes out when the query is dropped
                    self._answer(kind, payload)
            except Exception:
                self.counters.errors.labels(kind, "handler").inc()
                log.exception("serving a %s query failed", kind)

    def _answer(self, kind: str, query: zenoh.Query) -> None:
        data = query.payload.to_bytes() if query.payload is not None else b""
        handler = {"lease": self._lease, "results": self._results,
                   "object": lambda q, d: self._fetch(q, d, "object"),
                   "gripper": lambda q, d: self._fetch(q, d, "gripper")}[kind]
        cause: str | None = ""  # the log line's, never the reply's
        try:
            reply = handler(query, data)
            self.outage.succeeded()
        except Exception as exc:  # never its text in the reply; a batch is counted
            reply, cause = failed_reply(kind, exc, self.outage, lambda: self._count(
                data, "the coordinator could not store the batch"))
        if isinstance(reply, ErrorReply):
            self.counters.queries.labels(kind, "error").inc()
            self.counters.errors.labels(kind, reply.code.value).inc()
            if cause is not None:  # None: an outage, logged once per episode
                log.warning("%s query refused (%s): %s%s", kind, reply.code.value,
                            reply.message, cause)
            query.reply_err(encode(reply))
        else:
            self.counters.queries.labels(kind, "ok").inc()

    def _count(self, data: bytes, reason: str) -> str:
        """count_refusal for a refused batch's raw bytes ("" when nobody can be held to it)."""
        header = batch_header(data)
        if header is None:
            return ""
        try:
            with self._store_turn, self.sessions() as session:
                return count_refusal(session, header, reason,
                                     max_attempts=self.settings.queue.max_attempts,
                                     sessions=self.worker_sessions)
        except Exception:  # the refusal stands; the lease expiry remains
            log.debug("counting a refused batch failed", exc_info=True)
            return ""

    def _lease(self, query: zenoh.Query, data: bytes) -> ErrorReply | None:
        request = decode_as(data, LeaseRequest)
        if isinstance(request, ErrorReply):
            return request
        n = min(request.capacity, self.zenoh_settings.max_tiles_per_request)
        try:
            with self._store_turn, self.sessions() as session:
                leased = lease_for(session, request, n=n,
                                   lease_seconds=self.settings.queue.lease_seconds,
                                   contexts=self.contexts, sessions=self.worker_sessions)
        except WorkerIdTaken as exc:
            return error(ErrorCode.WORKER_ID_TAKEN, exc.message)
        if leased.lost:
            self.counters.tiles_requeued.labels("reply_lost").inc(leased.lost)
            log.info("%d tiles of %s whose lease reply was lost: queued again",
                     leased.lost, request.worker_id)
        for message in leased.messages():
            query.reply(keys.lease_reply_key(message.tile_id), encode(message))
        self.counters.tiles_leased.inc(len(leased.tiles))
        return None  # no tile: the empty answer tells the worker to back off

    def _results(self, query: zenoh.Query, data: bytes) -> ErrorReply | None:
        batch = decode_as(data, ResultBatch)
        if isinstance(batch, ErrorReply) and batch.code == ErrorCode.MALFORMED:
            # A result fails validation (a NaN, say): counted as an attempt of its tile.
            return error(batch.code, batch.message + self._count(data, "batch refused: "
                                                                 + batch.message))
        if isinstance(batch, ErrorReply):
            return batch
        self.counters.poses_received.inc(len(batch.results))
        with self._store_turn, self.sessions() as session:
            reported = report_batch(session, batch, sessions=self.worker_sessions,
                                    max_attempts=self.settings.queue.max_attempts)
        if isinstance(reported.reply, ErrorReply):
            return reported.reply
        if reported.released:
            self.counters.tiles_requeued.labels("released").inc()
        # Sent only now, after the batch is committed: the reply is the acknowledgement.
        query.reply(str(query.key_expr), encode(reported.reply))
        return None

    def _fetch(self, query: zenoh.Query, data: bytes, kind: str) -> ErrorReply | None:
        """A mesh or a gripper's archive by content hash."""
        with self.sessions() as session:
            answer = fetch_answer(session, data, kind)
        if isinstance(answer, ErrorReply):
            return answer
        query.reply(answer[0], encode(answer[1]))
        return None

    # -- lost workers ----------------------------------------------------------------------

    def _watch_lost(self) -> None:
        while True:
            key = self._lost_keys.get()
            if key is None:
                return
            try:
                self._lost(key)
            except Exception:
                self.counters.errors.labels("liveliness", "handler").inc()
                log.exception("re-queueing the tiles of %s failed; lease expiry remains the "
                              "backstop", key)

    def _lost(self, key: str) -> None:
        worker_id = keys.worker_of_alive_key(key)
        if worker_id is None:
            self.counters.errors.labels("liveliness", "bad_key").inc()
            log.warning("liveliness token on unexpected key %s", key)
            return
        self.counters.workers_lost.inc()
        with self._store_turn, self.sessions() as session:
            requeued, failed = requeue_lost(session, worker_ids=[worker_id],
                                            max_attempts=self.settings.queue.max_attempts)
        if requeued or failed:
            self.counters.tiles_requeued.labels("worker_lost").inc(requeued)
            log.info("worker %s lost: %d tiles queued again, %d failed", worker_id,
                     requeued, failed)

    def alive_workers(self, timeout_s: float = 2.0) -> set[str] | None:
        """Worker ids with a liveliness token now; None when it could not be asked."""
        return None if self._session is None else alive_workers(self._session, timeout_s)

    def _orphan_sweep(self) -> None:
        # Leases of workers that died while this coordinator was down (no DELETE will come):
        # after a grace period to reconnect, those of owners without a token are requeued.
        if self._stopping.wait(self.zenoh_settings.orphan_grace_s):
            return
        try:
            alive = self.alive_workers(timeout_s=5.0)  # a loaded router answers late
            if alive is None:
                return
            with self._store_turn, self.sessions() as session:
                if not lease_owners(session) - alive:
                    return
                requeued, failed = requeue_lost(session, alive=alive,
                                                max_attempts=self.settings.queue.max_attempts)
            self.counters.tiles_requeued.labels("orphaned").inc(requeued)
            log.info("leases of workers gone since before start: %d tiles queued again, "
                     "%d failed", requeued, failed)
        except Exception:
            self.counters.errors.labels("orphan_sweep", "handler").inc()
            log.exception("orphan sweep failed; lease expiry remains the backstop")
