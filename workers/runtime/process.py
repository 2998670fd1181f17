"""One simulation process: pull a tile, evaluate its poses, report, repeat.

Each process opens its own zenoh session after it started (a session never crosses a fork)
and declares a liveliness token on its own key, so the coordinator re-queues its tile the
moment it dies. SIGTERM or SIGINT: the pose being simulated is finished, the poses done are
sent with the rest of the tile released, and the process exits.
"""

from __future__ import annotations

import logging
import os
import secrets
import signal
import socket
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh
from graspscape.shared.heap import freeze_startup_heap
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import PoseResult
from graspscape.shared.wire import keys
from graspscape.shared.wire.codec import decode_as, decode_reply_error, encode
from graspscape.shared.wire.messages import (
    Ack,
    ErrorCode,
    LeaseRequest,
    ResultBatch,
    TileLease,
)
from graspscape.workers.runtime.backoff import Backoff
from graspscape.workers.runtime.config import WorkerConfig
from graspscape.workers.runtime.grippers import GripperCache
from graspscape.workers.runtime.instant import instant_result
from graspscape.workers.runtime.isolation import ErrorStreak, error_result, finite_or_error
from graspscape.workers.runtime.objects import ObjectCache, ObjectFetchError
from graspscape.workers.runtime.session import session_config
from graspscape.workers.runtime.watch import CoordinatorWatch, stop_with_parent

log = logging.getLogger("graspscape.worker")


class Stopped(Exception):
    """The process was told to stop while waiting for the coordinator."""


class WorkerProcess:
    def __init__(self, config: WorkerConfig, index: int) -> None:
        self.config = config
        self.worker_id = f"{config.name}-p{index}-{os.getpid()}"
        # Sent with every request: the coordinator binds the id to it (never logged).
        self.session_key = secrets.token_hex(16)
        self.stop = threading.Event()
        self.stop_deadline: float | None = None
        self.session: zenoh.Session | None = None
        self.tiles_done = 0
        self.poses_done = 0
        # The batch sent last, whose acknowledgement is not read yet: the next tile is
        # evaluated meanwhile (see _send).
        self.pending: _Delivery | None = None
        self.watch: CoordinatorWatch | None = None

    # -- lifecycle -----------------------------------------------------------------------

    def request_stop(self, *_: object) -> None:
        if not self.stop.is_set():
            self.stop_deadline = time.monotonic() + self.config.shutdown_grace_s
            self.stop.set()

    def run(self) -> None:
        signal.signal(signal.SIGTERM, self.request_stop)
        signal.signal(signal.SIGINT, self.request_stop)
        stop_with_parent(self.request_stop)
        try:
            self.session = self._open()
        except Stopped:
            return
        token = self.session.liveliness().declare_token(keys.alive_key(self.worker_id))
        cache_dir = self.config.cache_dir or _default_cache_dir()
        self.objects = ObjectCache(self.session, cache_dir, self.config.query_timeout_s)
        self.grippers = GripperCache(self.session, cache_dir, self.config.query_timeout_s)
        self.cache_dir = cache_dir
        log.info("%s connected to %s", self.worker_id, self.config.connect)
        freeze_startup_heap()
        try:
            self._loop()
        finally:
            self._settle()
            token.undeclare()
            self.session.close()
            log.info("%s stopped after %d tiles, %d poses", self.worker_id, self.tiles_done,
                     self.poses_done)

    def _open(self) -> zenoh.Session:
        backoff = Backoff(self.config.backoff_min_s, self.config.backoff_max_s)
        while not self.stop.is_set():
            try:
                return zenoh.open(session_config(self.config))
            except zenoh.ZError as exc:
                # zenoh refuses wrong credentials the same way (no other word of it here).
                log.info("%s: coordinator not reachable yet, or the login refused (%s)",
                         self.worker_id, exc)
                self.stop.wait(backoff.next())
        raise Stopped

    def _check_link(self) -> None:
        """Log where the coordinator went (called while waiting for it)."""
        if self.watch is None:
            self.watch = CoordinatorWatch(self.session, self.worker_id, self.config.connect)
        self.watch.check()

    def _loop(self) -> None:
        idle = Backoff(self.config.backoff_min_s, self.config.backoff_max_s)
        while not self.stop.is_set():
            tiles = self._lease()
            if not tiles:
                self._settle()
                self._check_link()
                self.stop.wait(idle.next())  # no work, or no coordinator: ask again later
                continue
            idle.reset()
            for tile in tiles:
                if self.stop.is_set():
                    # Not started: hand it back untouched.
                    self._deliver(self._batch(tile, [], final=False, release=True))
                    continue
                self._work(tile)

    # -- protocol ------------------------------------------------------------------------

    def _lease(self) -> list[TileLease]:
        request = LeaseRequest(
            worker_id=self.worker_id, session_key=self.session_key,
            host=socket.gethostname()[:255],
            capacity=self.config.tiles_per_request,
            # The tile whose batch is still on its way is not lost: it stays leased.
            holding=[self.pending.batch.tile_id] if self.pending is not None else [],
            engines=list(self.config.engines),
        )
        tiles: list[TileLease] = []
        try:
            replies = self.session.get(
                keys.LEASE_QUERY,
                payload=encode(request),
                consolidation=zenoh.ConsolidationMode.NONE,
                timeout=self.config.query_timeout_s,
            )
            for reply in replies:
                if reply.ok is not None:
                    message = decode_as(reply.ok.payload.to_bytes(), TileLease)
                else:
                    message = decode_reply_error(reply.err.payload.to_bytes())
                if isinstance(message, TileLease):
                    tiles.append(message)
                else:
                    # A tile whose reply cannot be read (or came too late) stays leased to
                    # this id; the next request (holding nothing) hands it back.
                    log.warning("%s: lease refused: %s: %s", self.worker_id, message.code,
                                message.message)
        except zenoh.ZError as exc:
            log.warning("%s: lease query failed: %s", self.worker_id, exc)
        return tiles

    def _work(self, tile: TileLease) -> None:
        try:
            poses = tile.poses()
        except ValueError as exc:  # pydantic's ValidationError: a pose out of range
            # The tile's fault, not this process's: reported failed with the reason, where a
            # crash would have the tile "lost" three times with no word of why.
            reason = f"the tile's poses are invalid: {exc}"
            log.error("%s: tile %d failed: %s", self.worker_id, tile.tile_id, reason)
            self._deliver(self._batch(tile, [], final=False, error=reason[:2000]))
            return
        batch = self._evaluate_tile(tile, poses)
        if batch is not None:
            self._send(batch, tile)
            self.poses_done += len(batch.results)
            self.tiles_done += batch.final

    def _evaluate_tile(self, tile: TileLease, poses: list[Pose]) -> ResultBatch | None:
        """Evaluate these poses of a tile: the batch to send (`final` when every one was
        evaluated, else `release` of the rest: told to stop), or None when the tile was
        reported failed or handed back here already."""
        results: list[PoseResult] = []
        try:
            obj = None if self.config.instant else self.objects.spec(tile.object)
            if not self.config.instant:  # fetched now, so that a failure is the tile's
                self.grippers.gripper(tile.gripper_ref, tile.gripper)
        except ObjectFetchError as exc:  # a mesh's or a gripper's (GripperFetchError)
            if not exc.transient:  # none with that hash, or a corrupt one: the tile fails here
                self._deliver(self._batch(tile, [], final=False, error=str(exc)))
                return None
            # The coordinator is unreachable right now: not the tile's fault, so it goes
            # back uncounted (delivered once the coordinator answers again).
            log.warning("%s: tile %d handed back: %s", self.worker_id, tile.tile_id, exc)
            self._deliver(self._batch(tile, [], final=False, release=True))
            self.stop.wait(self.config.backoff_max_s)
            return None
        donors = self._donors(tile)
        streak = ErrorStreak()
        for pose in poses:
            if self.stop.is_set():
                break
            try:  # every number checked: a NaN is the pose's error, never the batch's
                result = finite_or_error(self._evaluate(tile, obj, pose, donors))
            except Exception as exc:  # this pose cannot be evaluated: store why, go on
                log.exception("%s: tile %d: pose %s raised", self.worker_id, tile.tile_id,
                              pose.key())
                result = error_result(pose, exc)
            streak.record(result)
            if streak.systematic():  # every pose raises: the tile's fault, not the poses'
                reason = (f"the first {streak.evaluated} poses all raised; the last: "
                          f"{result.error}")
                log.error("%s: tile %d failed: %s", self.worker_id, tile.tile_id, reason)
                self._deliver(self._batch(tile, [], final=False, error=reason))
                return None
            results.append(result)
            log.debug("%s: tile %d: pose %d of %d evaluated", self.worker_id,
                      tile.tile_id, len(results), len(poses))
        final = len(results) == len(poses)
        return self._batch(tile, results, final=final, release=not final)

    def _complete(self, delivery: _Delivery, ack: Ack) -> None:
        """The coordinator stored a final batch but misses poses of the tile (`ack.missing`),
        so the tile is still leased to this process, unfinished. Evaluate those poses and
        send them, once, as the tile's final batch (in flight like any other). If they are
        not poses of this process's copy of the tile, or still missing after that, the tile
        is reported failed with the reason (an attempt counted, the reason in its
        last_error), so it never goes round for good."""
        tile = delivery.tile
        assert tile is not None
        wanted = set(ack.missing)
        poses = [pose for pose in tile.poses() if pose.key() in wanted]
        unknown = wanted - {pose.key() for pose in poses}
        if delivery.round or unknown:
            why = ("still misses after they were sent again" if delivery.round else
                   "misses, not in this worker's copy of the tile,")
            shown = sorted(unknown or wanted)
            reason = (f"the coordinator {why} {len(shown)} poses: {', '.join(shown[:5])}"
                      f"{' …' if len(shown) > 5 else ''}")
            log.error("%s: tile %d: %s; reporting the tile failed", self.worker_id,
                      tile.tile_id, reason)
            self._deliver(self._batch(tile, [], final=False, error=reason))
            return
        log.warning("%s: tile %d: the coordinator misses %d pose(s) of its final batch; "
                    "evaluating them again", self.worker_id, tile.tile_id, len(poses))
        batch = self._evaluate_tile(tile, poses)
        if batch is not None:
            self.pending = self._query(batch, tile=tile, round_=delivery.round + 1)
            self.poses_done += len(batch.results)

    def _donors(self, tile: TileLease):
        """Shortcut 2's pool for this tile (filled in the tile's pose order), if asked for."""
        if self.config.instant or tile.configuration_match is None:
            return None
        from graspscape.workers.sim.configuration_inference import DonorPool

        return DonorPool(tile.configuration_match)

    def _evaluate(self, tile: TileLease, obj, pose, donors=None) -> PoseResult:
        if self.config.instant:
            if self.config.instant_pose_s:
                self.stop.wait(self.config.instant_pose_s)
            return instant_result(pose, tile.sample)
        if tile.sample is not None:  # a success probability's draw: outcome only
            from graspscape.workers.sim.samples import tile_draw

            return tile_draw(pose, tile, obj, self.cache_dir)
        from graspscape.workers.sim.evaluate import evaluate_pose

        gripper = self.grippers.gripper(tile.gripper_ref, tile.gripper)  # in memory by now
        return evaluate_pose(pose, obj=obj, gripper=gripper, settings=tile.settings,
                             cache_dir=self.cache_dir, donors=donors)

    def _batch(self, tile: TileLease, results: list[PoseResult], *, final: bool,
               release: bool = False, error: str | None = None) -> ResultBatch:
        return ResultBatch(worker_id=self.worker_id, session_key=self.session_key,
                           tile_id=tile.tile_id,
                           lease_epoch=tile.lease_epoch, results=results, final=final,
                           release=release, error=error)

    def _deliver(self, batch: ResultBatch) -> Ack | None:
        """Send a batch until the coordinator acknowledges it (the ack means committed)."""
        self._settle()
        return self._await(self._query(batch))

    def _send(self, batch: ResultBatch, tile: TileLease | None = None) -> None:
        """Send a batch and go on: its acknowledgement is read after the next tile, so the
        coordinator commits one batch while this process evaluates the next. One batch at
        most is in flight; until its ack, it is retried as _deliver does. `tile`: the lease
        of a final batch, kept to evaluate poses the coordinator reports missing."""
        self._settle()
        self.pending = self._query(batch, tile=tile if batch.final else None)

    def _settle(self) -> Ack | None:
        """Wait for the batch in flight, if any, to be acknowledged (or given up). A final
        batch whose ack lists missing poses is completed first (_complete), which puts the
        completing batch in flight; it is settled here too."""
        ack = None
        while self.pending is not None:
            pending, self.pending = self.pending, None
            ack = self._await(pending)
            if ack is not None and ack.missing and pending.tile is not None:
                self._complete(pending, ack)
        return ack

    def _query(self, batch: ResultBatch, payload: bytes | None = None,
               tile: TileLease | None = None, round_: int = 0) -> _Delivery:
        payload = payload if payload is not None else encode(batch)
        key = keys.results_key(batch.tile_id, batch.lease_epoch)
        try:
            replies = self.session.get(
                key,
                payload=payload,
                consolidation=zenoh.ConsolidationMode.NONE,
                timeout=self.config.query_timeout_s,
            )
        except zenoh.ZError as exc:
            log.warning("%s: sending tile %d failed: %s", self.worker_id, batch.tile_id, exc)
            replies = None
        return _Delivery(batch, payload, replies, tile, round_)

    def _await(self, delivery: _Delivery) -> Ack | None:
        """Read a sent batch's answer; send it again until the coordinator acknowledges it."""
        batch = delivery.batch
        backoff = Backoff(self.config.backoff_min_s, self.config.backoff_max_s)
        while True:
            try:
                for reply in delivery.replies if delivery.replies is not None else ():
                    if reply.ok is not None:
                        message = decode_as(reply.ok.payload.to_bytes(), Ack)
                    else:
                        # zenoh's own Timeout (no ack within query_timeout_s: the coordinator
                        # may still be committing it) comes back as a retryable `unavailable`.
                        message = decode_reply_error(reply.err.payload.to_bytes())
                    if isinstance(message, Ack):
                        return message
                    if message.code == ErrorCode.NOT_LEASE_HOLDER:
                        # The tile's lease is no longer this process's (it ran out and the
                        # tile went to another worker): nothing to resend, the holder now
                        # evaluates it.
                        log.warning("%s: batch of tile %d dropped, the lease is gone: %s",
                                    self.worker_id, batch.tile_id, message.message)
                        return None
                    if not message.code.retryable:
                        log.error("%s: batch of tile %d refused for good: %s: %s",
                                  self.worker_id, batch.tile_id, message.code, message.message)
                        return None
                    log.warning("%s: batch of tile %d not acknowledged yet (%s); sending it "
                                "again", self.worker_id, batch.tile_id, message.message)
            except zenoh.ZError as exc:
                log.warning("%s: sending tile %d failed: %s", self.worker_id, batch.tile_id, exc)
            # No answer (coordinator down or restarting) or a retryable refusal.
            self._check_link()
            if self.stop_deadline is not None and time.monotonic() > self.stop_deadline:
                log.error("%s: gave up delivering tile %d at shutdown; it will be queued "
                          "again by the coordinator", self.worker_id, batch.tile_id)
                return None
            time.sleep(backoff.next())
            delivery = self._query(batch, delivery.payload, delivery.tile, delivery.round)


@dataclass
class _Delivery:
    """A result batch sent to the coordinator, and the replies to read."""

    batch: ResultBatch
    payload: bytes
    replies: Any  # zenoh's reply handler; None when the query could not be sent
    tile: TileLease | None = None  # a final batch's lease, to complete it (_complete)
    round: int = 0  # 1: the batch that completes a tile the coordinator found incomplete


def _default_cache_dir() -> Path:
    return Path(os.environ.get("GRASPSCAPE_CACHE_DIR", Path.home() / ".cache" / "graspscape"))


def process_main(config_json: str, index: int, log_level: str) -> None:
    """Entry point of a spawned process (arguments are plain strings: spawn pickles them)."""
    logging.basicConfig(level=log_level.upper(),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    WorkerProcess(WorkerConfig.model_validate_json(config_json), index).run()
