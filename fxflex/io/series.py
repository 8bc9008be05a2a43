"""Time series written while the run goes: a commented JSON header, then CSV rows.

Only rank 0 writes. Rows are flushed at least every ``flush_s`` seconds so that an interrupted
run leaves a readable file holding everything computed up to the last flush. The writer counts
the bytes it has written and hashes them (SHA-256), so that a checkpoint can record exactly which
prefix of the file belongs to it; ``resume=(bytes, sha256)`` reopens such a file, checks the
prefix, cuts whatever a killed run wrote after it and appends from there.
"""

from __future__ import annotations

import hashlib
import json
import os
import time

from fxflex.errors import FxflexError

__all__ = ["SeriesWriter", "read_series", "prefix_digest"]


def prefix_digest(path: str | os.PathLike, size: int) -> str | None:
    """SHA-256 of the first ``size`` bytes of a file, or None if it is shorter."""
    h = hashlib.sha256()
    left = size
    with open(path, "rb") as fh:
        while left > 0:
            chunk = fh.read(min(left, 1 << 20))
            if not chunk:
                return None
            h.update(chunk)
            left -= len(chunk)
    return h.hexdigest()


class SeriesWriter:
    def __init__(self, path: str | os.PathLike, meta: dict, columns: list[str], *,
                 resume: tuple[int, str] | None = None, enabled: bool = True,
                 flush_s: float = 0.5):
        self.enabled = enabled
        self.columns = columns
        self.flush_s = flush_s
        self.path = os.fspath(path)
        self._fh = None
        self._hash = hashlib.sha256()
        self.bytes = 0
        if not enabled:
            return
        if resume is None:
            self._fh = open(path, "wb", buffering=1 << 16)
            head = "".join(f"# {line}\n" for line in json.dumps(meta).splitlines())
            self._put(head + ",".join(columns) + "\n")
            self._fh.flush()
        else:
            size, digest = resume
            if not os.path.isfile(path) or prefix_digest(path, size) != digest:
                raise FxflexError(f"--resume: {self.path} does not begin with the {size} bytes "
                                  "the checkpoint recorded (a different or shortened file)")
            with open(path, "rb") as fh:
                self._hash.update(fh.read(size))
            self.bytes = size
            os.truncate(path, size)             # rows a killed run wrote after the checkpoint
            self._fh = open(path, "ab", buffering=1 << 16)
        self._last = time.monotonic()

    def _put(self, text: str) -> None:
        data = text.encode()
        self._fh.write(data)
        self._hash.update(data)
        self.bytes += len(data)

    def write(self, row) -> None:
        if self._fh is None:
            return
        self._put(",".join(f"{x:.12g}" for x in row) + "\n")
        now = time.monotonic()
        if now - self._last > self.flush_s:
            self._fh.flush()
            self._last = now

    def sync(self) -> tuple[int, str]:
        """Flush to disk (fsync); (bytes written, SHA-256 of them) for a checkpoint."""
        if self._fh is not None:
            self._fh.flush()
            os.fsync(self._fh.fileno())
        return self.bytes, self._hash.hexdigest()

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
