"""``--workers 1`` without ``--prefetch``: one pair after the other, in this process."""

from __future__ import annotations

from typing import Callable, Iterator, Sequence

from .. import warmup


class SerialExecutor:
    """One pair after the other in this process."""

    mode = "serial"

    def __init__(self):
        self.current = None  # the pair in progress, for run.json after an interruption

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def describe(self) -> dict:
        return {"mode": self.mode, "workers": 1}

    def warm(self, cfg, method) -> float:
        return warmup.warm_jit(cfg, method)

    def drain(self) -> list:
        """Pairs finished after an interruption: none here (the pair in progress is dropped)."""
        return []

    def imap(self, task: Callable, pairs: Sequence) -> Iterator:
        """Yield ``(pair, task(pair))`` in order."""
        for pair in pairs:
            self.current = pair
            result = task(pair)
            self.current = None
            yield pair, result
