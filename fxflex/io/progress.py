"""A progress line on stderr for long runs (rank 0 only, silent for short ones)."""

from __future__ import annotations

import sys
import time

__all__ = ["Progress"]


class Progress:
    """Shows ``label  42%  t=...  elapsed  eta`` once the task has run ``delay`` seconds."""

    def __init__(self, total: int, label: str, *, enabled: bool = True, delay: float = 2.0,
                 every: float = 0.5, stream=None):
        self.total, self.label = max(int(total), 1), label
        self.enabled = enabled
        self.delay, self.every = delay, every
        self.stream = stream or sys.stderr
        self.t0 = time.monotonic()
        self._last = self.t0
        self._shown = False

    def update(self, done: int, note: str = "") -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self.t0 < self.delay or now - self._last < self.every:
            return
        self._last = now
        frac = min(done / self.total, 1.0)
        elapsed = now - self.t0
        eta = elapsed * (1 - frac) / frac if frac > 0 else float("nan")
        self.stream.write(f"\r{self.label}  {100 * frac:5.1f}%  {note}  elapsed {elapsed:6.1f} s"
                          f"  eta {eta:6.1f} s ")
        self.stream.flush()
        self._shown = True

    def close(self, note: str = "") -> None:
        if self.enabled and self._shown:
            elapsed = time.monotonic() - self.t0
            self.stream.write(f"\r{self.label}  done  {note}  in {elapsed:.1f} s"
                              + " " * 30 + "\n")
            self.stream.flush()
