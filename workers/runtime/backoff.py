"""Exponential backoff with jitter, so that many idle workers do not ask in lockstep."""

from __future__ import annotations

import random


class Backoff:
    def __init__(self, low: float, high: float) -> None:
        self.low, self.high = low, high
        self.current = low

    def next(self) -> float:
        delay = self.current * random.uniform(0.5, 1.0)
        self.current = min(self.high, self.current * 2)
        return delay

    def reset(self) -> None:
        self.current = self.low
