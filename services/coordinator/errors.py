"""Domain errors raised by the services; the web layer maps each to one HTTP status.

Messages are written for the user: they name the object and the problem, because they are
returned verbatim as the `detail` of the 4xx response.
"""

from __future__ import annotations


class CoordinatorError(Exception):
    status_code = 400

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message


class NotFound(CoordinatorError):
    status_code = 404


class Conflict(CoordinatorError):
    status_code = 409


class NotLeaseHolder(Conflict):
    """A worker's report for a tile whose latest lease is not the one it names (another
    worker holds it, or it was leased again since): refused whole, nothing stored."""


class WorkerIdTaken(Conflict):
    """A lease request or batch under a worker id that another session registered."""


class InvalidInput(CoordinatorError):
    status_code = 422

    def __init__(self, message: str, loc: tuple[str | int, ...] = ("body",)) -> None:
        super().__init__(message)
        self.loc = loc


class PayloadTooLarge(CoordinatorError):
    status_code = 413


class UnsupportedMediaType(CoordinatorError):
    status_code = 415
