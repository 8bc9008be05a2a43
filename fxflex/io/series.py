"""Time series written while the run goes: a commented JSON header, then CSV rows.

Only rank 0 writes. Rows are flushed at least every ``flush_s`` seconds so that an interrupted
run leaves a readable file holding everything computed up to the last flush. The writer counts
the bytes it has written and hashes them (SHA-256), so that a checkpoint can record exactly which
prefix of the file belongs to it; ``resume=(bytes, sha256)`` reopens such a file, checks the
prefix, cuts whatever a killed run wrote after it and appends from there.

A write that fails (disk full, file size limit) leaves no half-written series: the file goes
back to what the last checkpoint recorded (``keep``), to its size before a resumed run, or - a
new file no checkpoint refers to - is removed; the error is an :class:`OutputError` saying which.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import time

from fxflex.errors import FxflexError, OutputError

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
    """Rank 0's CSV series; every method raises :class:`OutputError` when the file cannot be
    written, after putting it back to a consistent state (:meth:`abandon`)."""

    def __init__(self, path: str | os.PathLike, meta: dict, columns: list[str], *,
                 resume: tuple[int, str] | None = None, enabled: bool = True,
                 flush_s: float = 0.5, flag: str = "--out"):
        self.enabled = enabled
        self.columns = columns
        self.flush_s = flush_s
        self.flag = flag
        self.path = os.fspath(path)
        self._fh = None
        self._hash = hashlib.sha256()
        self.bytes = 0
        self.kept = None            # bytes a checkpoint refers to; None: a new file, no checkpoint
        self._opened = False
        self._abandoned = None
        if not enabled:
            return
        if resume is None:
            head = "".join(f"# {line}\n" for line in json.dumps(meta).splitlines())
            with self._guard():
                self._fh = open(path, "wb", buffering=1 << 16)
                self._opened = True
                self._put(head + ",".join(columns) + "\n")
                self._fh.flush()
        else:
            size, digest = resume
            if not os.path.isfile(path) or prefix_digest(path, size) != digest:
                raise FxflexError(f"--resume: {self.path} does not begin with the {size} bytes "
                                  "the checkpoint recorded (a different or shortened file)")
            with open(path, "rb") as fh:
                self._hash.update(fh.read(size))
            self.bytes = self.kept = size
            with self._guard():
                os.truncate(path, size)         # rows a killed run wrote after the checkpoint
                self._fh = open(path, "ab", buffering=1 << 16)
        self._last = time.monotonic()

    @contextlib.contextmanager
    def _guard(self):
        """An OSError inside the block becomes an OutputError, after :meth:`abandon`."""
        try:
            yield
        except OSError as exc:
            done = self.abandon()
            raise OutputError(f"{self.flag}: cannot write {self.path}: {exc.strerror or exc}; "
                              f"{done}") from None

    def _put(self, text: str) -> None:
        data = text.encode()
        self._fh.write(data)
        self._hash.update(data)
        self.bytes += len(data)

    def write(self, row) -> None:
        if self._fh is None:
            return
        with self._guard():
            self._put(",".join(f"{x:.12g}" for x in row) + "\n")
            now = time.monotonic()
            if now - self._last > self.flush_s:
                self._fh.flush()
                self._last = now

    def sync(self) -> tuple[int, str]:
        """Flush to disk (fsync); (bytes written, SHA-256 of them) for a checkpoint."""
        if self._fh is not None:
            with self._guard():
                self._fh.flush()
                os.fsync(self._fh.fileno())
        return self.bytes, self._hash.hexdigest()

    def keep(self, size: int) -> None:
        """A checkpoint now refers to the first ``size`` bytes: a failure cuts back to them."""
        self.kept = size

    def close(self) -> None:
        if self._fh is not None:
            with self._guard():
                self._fh.flush()
                os.fsync(self._fh.fileno())
                self._fh.close()
            self._fh = None

    def close_after(self, exc: BaseException) -> None:
        """Clean up after ``exc`` stopped the run: a failed write (:class:`OutputError`) leaves
        no half-written series (:meth:`abandon`); anything else keeps what was written, flushed
        (:meth:`close`), a second output failure there not raised over ``exc``."""
        if isinstance(exc, OutputError):
            self.abandon()
            return
        try:
            self.close()
        except OutputError:
            pass

    def abandon(self) -> str:
        """Stop writing and put the file back to what a checkpoint refers to (or remove a new
        file none refers to); what was done, for the error message."""
        if not self.enabled:
            return ""
        if self._abandoned is None:
            self._abandoned = self._restore()
        return self._abandoned

    def _restore(self) -> str:
        if self.kept is None and not self._opened:
            return "nothing was written"
        if self._fh is not None:
            try:
                self._fh.close()
            except OSError:
                pass                    # the buffered rows that failed are dropped below
            self._fh = None
        try:
            if self.kept is None:
                os.unlink(self.path)
                return f"the unfinished {self.path} was removed"
            os.truncate(self.path, self.kept)
            return f"{self.path} was cut back to the {self.kept} bytes of the last checkpoint"
        except OSError as exc:
            return f"{self.path} could not be cleaned up either ({exc.strerror or exc})"

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
