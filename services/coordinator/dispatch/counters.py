"""Prometheus counters of the dispatch, registered in the app's own registry (/metrics).

Zenoh swallows exceptions raised in callbacks, so every refusal and failure is counted here
as well as logged: a rising error count is how an operator sees them.
"""

from __future__ import annotations

from prometheus_client import CollectorRegistry, Counter


class DispatchCounters:
    def __init__(self, registry: CollectorRegistry | None = None) -> None:
        registry = registry or CollectorRegistry()
        self.queries = Counter(
            "graspscape_dispatch_queries",
            "zenoh queries served, by kind and outcome",
            ["kind", "outcome"],
            registry=registry,
        )
        self.errors = Counter(
            "graspscape_dispatch_errors",
            "dispatch errors, by where and error code",
            ["where", "code"],
            registry=registry,
        )
        self.tiles_leased = Counter(
            "graspscape_dispatch_tiles_leased", "tiles handed to workers", registry=registry
        )
        self.poses_received = Counter(
            "graspscape_dispatch_poses_received",
            "pose results received (new and duplicate)",
            registry=registry,
        )
        self.tiles_requeued = Counter(
            "graspscape_dispatch_tiles_requeued",
            "tiles put back in the queue by the dispatch, by reason",
            ["reason"],
            registry=registry,
        )
        self.workers_lost = Counter(
            "graspscape_dispatch_workers_lost",
            "worker processes whose liveliness token vanished",
            registry=registry,
        )
