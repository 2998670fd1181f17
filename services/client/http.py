"""`Client`: the coordinator's REST API from Python, on httpx.

    from graspscape.services.client import Client

    with Client("http://127.0.0.1:8000") as api:
        obj = api.add_object("mug")
        run = api.submit({"object_id": obj.id, "grid": {"dtheta": 0.52}})
        api.wait(run.id, progress=lambda e: print(e.poses_done, "/", e.poses_total))
        best = api.best(run.id)
        print(best.poses[0].transform)  # 4×4 numpy

Reads are retried on connection errors and 502/503/504 answers (a coordinator restarting
behind a proxy); a refusal (4xx) raises `ApiError` with the server's detail at once.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NoReturn

import httpx
from graspscape.services.client.models import (
    Best,
    Exploration,
    FailedTile,
    Manifolds,
    Pose,
    Retried,
    StoredGripper,
    StoredObject,
    Submitted,
)
from pydantic import BaseModel

_TRANSIENT = frozenset({502, 503, 504})
EXPORTS = ("poses.csv", "poses.parquet", "manifolds.json", "graspgen.json", "acronym.h5",
           "object.obj")


class ApiError(RuntimeError):
    """The coordinator refused a request: its status and the detail it gave."""

    def __init__(self, status: int, detail: Any, url: str) -> None:
        self.status, self.detail, self.url = status, detail, url
        super().__init__(f"{status} from {url}: {_detail_text(detail)}")


def _detail_text(detail: Any) -> str:
    if isinstance(detail, list):  # FastAPI's validation errors: one line per location
        return "; ".join(f"{'.'.join(str(p) for p in d.get('loc', ()))}: {d.get('msg')}"
                         if isinstance(d, dict) else str(d) for d in detail)
    return str(detail)


class Client:
    """One coordinator. `token`: the API token its mutating routes demand, when set."""

    def __init__(self, url: str = "http://127.0.0.1:8000", *, token: str | None = None,
                 timeout_s: float = 30.0, retries: int = 3, backoff_s: float = 0.5,
                 transport: httpx.BaseTransport | None = None) -> None:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        self.retries, self.backoff_s = retries, backoff_s
        self._http = httpx.Client(base_url=url.rstrip("/"), headers=headers, timeout=timeout_s,
                                  transport=transport)

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._http.close()

    def _request(self, method: str, path: str, **kwargs: Any) -> httpx.Response:
        # Only reads are repeated after an answer: a POST answered 503 may have been applied.
        attempts = 1 + max(0, self.retries)
        for attempt in range(attempts):
            last = attempt == attempts - 1
            try:
                response = self._http.request(method, path, **kwargs)
            except httpx.TransportError:
                # A connection never made sent nothing: safe to try again for any method.
                if last:
                    raise
                time.sleep(self.backoff_s * 2 ** attempt)
                continue
            if response.status_code in _TRANSIENT and method == "GET" and not last:
                time.sleep(self.backoff_s * 2 ** attempt)
                continue
            if response.status_code >= 400:
                self._raise(response)
            return response
        raise AssertionError("unreachable")

    def _get(self, path: str, model: type[Any], **params: Any) -> Any:
        given = {k: v for k, v in params.items() if v is not None}
        return model.model_validate(self._request("GET", path, params=given).json())

    # Objects and explorations.
    def add_object(self, name: str | None = None, *, mesh: Path | str | None = None,
                   **properties: Any) -> StoredObject:
        """Store an object by name (built-in, pb:…, ycb:…) or by uploading a mesh file;
        properties: mass_kg, friction, scale, units."""
        data = {k: str(v) for k, v in properties.items() if v is not None}
        if mesh is not None:
            path = Path(mesh)
            with path.open("rb") as f:
                answer = self._request("POST", "/objects", data=data,
                                       files={"file": (path.name, f)})
        else:
            answer = self._request("POST", "/objects", data={**data, "name": name or ""})
        return StoredObject.model_validate(answer.json())

    def add_gripper(self, path: Path | str) -> StoredGripper:
        """Upload a gripper of one's own: a TOML spec file, or a URDF gripper's folder (zipped
        here, its files only). Name it in a spec by the answer's `gripper` ('sha256:…'); the
        coordinator ships it to the workers."""
        from graspscape.shared.specs.gripper import URDF_DESCRIPTION
        from graspscape.shared.specs.gripper_archive import folder_files, pack

        path = Path(path).expanduser()
        folder = path.parent if path.name == URDF_DESCRIPTION else path
        if folder.is_dir():
            upload = (f"{folder.name or 'gripper'}.zip", pack(folder_files(folder)))
        else:
            upload = (path.name, path.read_bytes())
        answer = self._request("POST", "/grippers", files={"file": upload})
        return StoredGripper.model_validate(answer.json())

    def submit(self, spec: BaseModel | dict[str, Any]) -> Submitted:
        body = spec.model_dump(mode="json") if isinstance(spec, BaseModel) else spec
        return Submitted.model_validate(self._request("POST", "/explorations", json=body).json())

    def status(self, exploration_id: int) -> Exploration:
        return self._get(f"/explorations/{exploration_id}", Exploration)

    def wait(self, exploration_id: int, *, poll_s: float = 1.0, timeout_s: float | None = None,
             progress: Callable[[Exploration], None] | None = None) -> Exploration:
        """Poll until the exploration finishes (done, incomplete, failed or cancelled); calls
        `progress` with each answer. TimeoutError after `timeout_s`."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            state = self.status(exploration_id)
            if progress is not None:
                progress(state)
            if state.finished:
                return state
            if deadline is not None and time.monotonic() > deadline:
                raise TimeoutError(f"exploration {exploration_id} is still {state.status} "
                                   f"after {timeout_s} s")
            time.sleep(poll_s)

    def cancel(self, exploration_id: int) -> Exploration:
        answer = self._request("POST", f"/explorations/{exploration_id}/cancel")
        return Exploration.model_validate(answer.json())

    def failures(self, exploration_id: int) -> list[FailedTile]:
        """Every failed tile, with its attempts and last error."""
        tiles: list[FailedTile] = []
        while True:
            page = self._request("GET", f"/explorations/{exploration_id}/failures",
                                 params={"limit": 500, "offset": len(tiles)}).json()
            tiles += [FailedTile.model_validate(t) for t in page["items"]]
            if not page["items"] or len(tiles) >= page["total"]:
                return tiles

    def retry(self, exploration_id: int) -> Retried:
        """Queue the failed tiles again (ApiError 409 where there are none)."""
        answer = self._request("POST", f"/explorations/{exploration_id}/retry")
        return Retried.model_validate(answer.json())

    # The map.
    def manifolds(self, exploration_id: int) -> Manifolds:
        return self._get(f"/explorations/{exploration_id}/manifolds", Manifolds)

    def best(self, exploration_id: int, *, manifold: str | None = None, limit: int = 1,
             rank: str | None = None, **constraints: Any) -> Best:
        """The best grasps; constraints as GET …/best's query (cone_x, cone_y, cone_z,
        cone_half_angle_deg, max_effort_nm, pose_error_mm, pose_error_deg, engines; on a
        table, resting=k for the group's exploration at resting pose k)."""
        return self._get(f"/explorations/{exploration_id}/best", Best, manifold=manifold,
                         limit=limit, rank=rank, **constraints)

    def poses(self, exploration_id: int, *, page_size: int = 500,
              **filters: Any) -> Iterator[Pose]:
        """Every stored pose matching GET …/poses' filters (viable, outcome, manifold_id,
        mu_min, …), page by page."""
        cursor = None
        while True:
            params = {k: v for k, v in {**filters, "limit": page_size,
                                        "cursor": cursor}.items() if v is not None}
            page = self._request("GET", f"/explorations/{exploration_id}/poses",
                                 params=params).json()
            yield from (Pose.model_validate(p) for p in page["items"])
            cursor = page.get("next_cursor")
            if cursor is None:
                return

    def export(self, exploration_id: int, what: str, path: Path | str) -> Path:
        """Stream one export (`EXPORTS`) to `path`; a dataset (graspgen.json, acronym.h5) comes
        with the object's mesh written beside it under the name its `object.file` gives."""
        if what not in EXPORTS:
            raise ValueError(f"what: one of {', '.join(EXPORTS)}, not {what!r}")
        path = Path(path)
        self._download(f"/explorations/{exploration_id}/export/{what}", path)
        if what in ("graspgen.json", "acronym.h5"):
            self._download(f"/explorations/{exploration_id}/export/object.obj",
                           path.with_name(object_file_name(exploration_id)))
        return path

    def _download(self, route: str, path: Path) -> None:
        part = path.with_name(path.name + ".part")
        for attempt in range(1 + max(0, self.retries)):
            try:
                with self._http.stream("GET", route) as response:
                    if response.status_code >= 400:
                        response.read()
                        self._raise(response)
                    with part.open("wb") as out:
                        for block in response.iter_bytes():
                            out.write(block)
                break
            except httpx.TransportError:
                part.unlink(missing_ok=True)
                if attempt == self.retries:
                    raise
                time.sleep(self.backoff_s * 2 ** attempt)
        part.replace(path)

    @staticmethod
    def _raise(response: httpx.Response) -> NoReturn:
        try:
            body = response.json()
            detail = body.get("detail", body) if isinstance(body, dict) else body
        except ValueError:
            detail = response.text
        raise ApiError(response.status_code, detail, str(response.url))


def object_file_name(exploration_id: int) -> str:
    """The mesh file a REST dataset export names in `object.file` (the download name of
    GET …/export/object.obj)."""
    return f"exploration-{exploration_id}-object.obj"
