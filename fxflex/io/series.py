"""Time series written while the run goes: a commented JSON header, then CSV rows.

Only rank 0 writes. Rows are flushed at least every ``flush_s`` seconds so that an interrupted
run leaves a readable file holding everything computed up to the last flush.
"""

from __future__ import annotations

import json
import os
import time

__all__ = ["SeriesWriter", "read_series"]


class SeriesWriter:
    def __init__(self, path: str | os.PathLike, meta: dict, columns: list[str], *,
                 append: bool = False, enabled: bool = True, flush_s: float = 0.5):
        self.enabled = enabled
        self.columns = columns
        self.flush_s = flush_s
        self._fh = None
        if not enabled:
            return
        self._fh = open(path, "a" if append else "w", buffering=1 << 16)
        if not append:
            for line in json.dumps(meta, indent=None, sort_keys=False).splitlines():
                self._fh.write(f"# {line}\n")
            self._fh.write(",".join(columns) + "\n")
            self._fh.flush()
        self._last = time.monotonic()

    def write(self, row) -> None:
        if self._fh is None:
            return
        self._fh.write(",".join(f"{x:.12g}" for x in row) + "\n")
        now = time.monotonic()
        if now - self._last > self.flush_s:
            self._fh.flush()
            self._last = now

    def close(self) -> None:
        if self._fh is not None:
            self._fh.flush()
            os.fsync(self._fh.fileno())
            self._fh.close()
            self._fh = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def read_series(path: str | os.PathLike):
    """(meta, columns, data) of a file written by :class:`SeriesWriter`; data is a 2-D array."""
    import numpy as np

    header, columns, rows = [], None, []
    with open(path) as fh:
        for line in fh:
            if line.startswith("#"):
                header.append(line[2:])
            elif columns is None:
                columns = line.strip().split(",")
            elif line.strip():
                parts = line.strip().split(",")
                if len(parts) == len(columns):      # a torn last line from a killed run
                    rows.append([float(x) for x in parts])
    meta = json.loads("".join(header)) if header else {}
    data = np.array(rows).reshape(-1, len(columns or []))
    return meta, columns, data
