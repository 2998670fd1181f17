"""bench_query's clients (also query_overhead's): the routes asked, and CLIENTS threads that
send each route's requests over loopback HTTP to the coordinator, as fast as answers come."""

from __future__ import annotations

import http.client
import random
import threading
import time

CLIENTS = 8


def routes(eid: int, max_id: int) -> dict[str, tuple[object, int]]:
    """Route name → (path or a function of a Random giving one, requests per client)."""
    base = f"/explorations/{eid}"
    return {
        "best": (f"{base}/best?limit=5", 6),
        "best_mu_s": (f"{base}/best?limit=5&rank=mu_s", 6),
        "best_torque_margin_ratio": (f"{base}/best?limit=5&rank=torque_margin_ratio", 6),
        "best_manifold": (f"{base}/best?limit=5&manifold=B", 6),
        "best_effort": (f"{base}/best?limit=5&max_effort_nm=2.0", 6),
        "best_cone": (f"{base}/best?limit=5&cone_x=0&cone_y=1&cone_z=0&cone_half_angle_deg=30",
                      6),
        "manifolds": (f"{base}/manifolds", 6),
        "manifold_label": (f"{base}/manifolds/A", 6),
        "poses_page": (lambda rng: f"{base}/poses?limit=100&cursor={rng.randrange(max_id)}", 6),
        "poses_viable_page": (
            lambda rng: f"{base}/poses?limit=100&viable=true&cursor={rng.randrange(max_id)}", 6),
        "map_png": (f"{base}/map.png", 2),
        "csv_first_byte": (f"{base}/export/poses.csv", 1),
    }


# The clients' library: "http.client" (the standard library's) or "httpx" (what the runs
# before 2026-12-03 18:00 used). Both send the same GETs over one keep-alive connection per
# thread and read every answer whole (the CSV to its first byte). The clients run on the same
# 2 cores as the server, so their CPU per request (bench_query's client_cpu figures) is part
# of what 8 clients wait for.
CLIENT = "http.client"


def _one(client, path: str, first_byte: bool) -> float:  # type: ignore[no-untyped-def]
    start = time.perf_counter()
    if first_byte:
        with client.stream("GET", path) as response:
            response.raise_for_status()
            if next(response.iter_raw(), None) is None:
                raise RuntimeError(f"{path}: an empty body")
    else:
        response = client.get(path)
        response.raise_for_status()
    return (time.perf_counter() - start) * 1000


def _one_plain(conn: http.client.HTTPConnection, path: str, first_byte: bool) -> float:
    start = time.perf_counter()
    conn.request("GET", path)
    response = conn.getresponse()
    if response.status >= 400:
        raise RuntimeError(f"{path}: {response.status} {response.read()[:200]!r}")
    if first_byte:
        if not response.read(1):
            raise RuntimeError(f"{path}: an empty body")
        conn.close()  # the rest of the stream is not wanted; the next request reconnects
    else:
        response.read()
    return (time.perf_counter() - start) * 1000


def run_route(base: str, name: str, path: object, per_client: int) -> list[float]:
    """`per_client` requests from each of CLIENTS threads at once; latencies in ms."""
    import httpx

    latencies: list[float] = []
    errors: list[BaseException] = []
    lock = threading.Lock()
    go = threading.Barrier(CLIENTS)
    host, port = base.removeprefix("http://").rsplit(":", 1)

    def client_loop(seed: int) -> None:
        rng = random.Random(seed)
        try:
            if CLIENT == "httpx":
                client: object = httpx.Client(base_url=base, timeout=600)
                one = _one
            else:
                client = http.client.HTTPConnection(host, int(port), timeout=600)
                one = _one_plain  # type: ignore[assignment]
            try:
                go.wait()
                for _ in range(per_client):
                    p = path(rng) if callable(path) else path
                    ms = one(client, str(p), name == "csv_first_byte")
                    with lock:
                        latencies.append(ms)
            finally:
                client.close()  # type: ignore[attr-defined]
        except BaseException as exc:  # reported after the join
            errors.append(exc)

    threads = [threading.Thread(target=client_loop, args=(i,)) for i in range(CLIENTS)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    if errors:
        raise errors[0]
    return latencies
