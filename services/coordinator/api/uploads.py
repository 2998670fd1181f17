"""Size limits of uploaded files (POST /objects, POST /grippers), refused as 413 naming the
limit: a body clearly over it before anything is parsed, else the file as it is read."""

from __future__ import annotations

from fastapi import Request, UploadFile
from graspscape.services.coordinator.errors import PayloadTooLarge

# Multipart overhead on top of the file is small: a body larger than the limit by more than
# this cannot hold a file within it.
MULTIPART_SLACK = 64 * 1024


def refuse_large_body(request: Request, limit: int) -> None:
    """Refuses outright a body whose declared length cannot hold a file within `limit`."""
    length = request.headers.get("content-length")
    if length and length.isdigit() and int(length) > limit + MULTIPART_SLACK:
        raise PayloadTooLarge(f"request body is larger than the upload limit of {limit} bytes")


def read_limited(upload: UploadFile, limit: int, what: str) -> bytes:
    """The file's bytes, refused (naming it as `what`) where there are more than `limit`."""
    data = upload.file.read(limit + 1)
    if len(data) > limit:
        raise PayloadTooLarge(f"{what} is larger than the upload limit of {limit} bytes")
    return data
