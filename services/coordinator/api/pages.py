"""The two page shapes of the list routes, generic over the item type.

`Page[T]` pages by offset (explorations, failed tiles, workers, objects: small, ordered lists
with a total); `CursorPage[T]` pages by keyset (an exploration's poses: millions of rows, where
an offset would rescan every earlier row and the total would cost a full count).

Items may be given as ORM rows: every item model reads attributes (`from_attributes`).
"""

from __future__ import annotations

from typing import Generic, TypeVar

from pydantic import BaseModel, Field

T = TypeVar("T", bound=BaseModel)


class Page(BaseModel, Generic[T]):
    items: list[T]
    total: int = Field(description="items matching, over every page")
    limit: int
    offset: int


class CursorPage(BaseModel, Generic[T]):
    items: list[T]
    limit: int
    next_cursor: int | None = Field(description="pass as ?cursor= for the next page; null at end")
