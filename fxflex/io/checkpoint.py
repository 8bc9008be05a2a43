"""Checkpoints of a running ``fxflex run`` and what ``--resume`` needs to continue it exactly.

A checkpoint is one ``.npz`` file (numpy's zip of arrays), written by rank 0 to a temporary file
in the same folder, fsynced and renamed over the previous one, so that a kill at any moment
leaves either the old or the new checkpoint, never a torn one. It holds

- ``meta``: JSON text - ``format``, ``fxflex_version``, the full ``scene`` and ``scene_hash``, the
  run ``settings`` that decide every number computed (method, integrator, dt_s, t_end_s,
  sample_every, force_eval, mass, rho_inf), the global ``step`` and time ``t_s`` reached, the
  number of ``samples`` written, for a variable-step run (``--tol``) the controller's ``clock``
  (time, next step, counters: fxflex.time.adaptive.Clock), the CSV series (``path``, ``bytes`` written up to this step and
  their ``sha256``; flushed and fsynced before the checkpoint is renamed into place), the
  checkpoint interval, the ``layout`` of the arrays and the rank count that wrote it;
- ``q``, ``v``: the state at ``step``; ``scheme/NAME``: the integrator's history arrays
  (``state_arrays()``: AB2 v_prev, a_prev; CD a, v_{n+1/2}).

MPI (TLF, the one distributed formulation): every array is gathered on rank 0 in a canonical node
order - nodes sorted by their undeformed coordinates (x, y, z; rounded to 1e-9 of the body's
extent, since dof coordinates can differ in the last bits between partitions), three entries
per node - and
scattered back by the same rule on resume. The file therefore does not depend on the partition:
a run checkpointed on 2 ranks can continue on 1 or 4. It continues bit for bit only on the same
rank count (the assembly order follows the partition); on another it agrees to round-off.
Replicated formulations (every other method) store their arrays as they are.

A checkpoint that cannot be written (disk full, the folder made read-only during the run) stops
the run on every rank with an :class:`~fxflex.errors.OutputError` naming the last good one;
``--resume`` refuses, with one line, a file that is not a whole checkpoint (truncated, not a zip,
meta missing) and a state holding NaN or inf, which no run could continue from.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

from fxflex import __version__
from fxflex.errors import FxflexError, OutputError

__all__ = ["Layout", "CheckpointWriter", "load_checkpoint", "check_settings", "FORMAT"]

FORMAT = "fxflex-checkpoint/1"


class Layout:
    """Maps this rank's state entries to the canonical global vector of a checkpoint.

    Formulations whose state is a set of nodes (3 entries each) offer ``state_points()``: the
    undeformed coordinates of the nodes this rank owns, in state order. Collective on form.comm.
    """

    def __init__(self, form):
        self.comm = form.comm
        points_fn = form.state_points
        self.kind = "replicated" if points_fn is None else "canonical-node-order"
        self._entries = None            # rank 0: canonical index of each gathered entry
        self._counts = None
        if points_fn is None:
            return
        points = np.ascontiguousarray(points_fn(), dtype=float)
        gathered = self.comm.gather(points, root=0)
        if self.comm.rank == 0:
            allp = np.vstack(gathered)
            # dof coordinates are evaluated cell by cell and may differ in the last bits between
            # partitions: sort on a grid of 1e-9 of the body's extent (nodes are far coarser)
            grid = 1e-9 * max(float(np.ptp(allp, axis=0).max()), 1e-300)
            allp = np.round(allp / grid)
            order = np.lexsort(allp.T[::-1])          # sort by x, then y, then z
            pos = np.empty(len(allp), dtype=np.int64)
            pos[order] = np.arange(len(allp))
            self._entries = (3 * pos[:, None] + np.arange(3)).reshape(-1)
            self._counts = [3 * len(p) for p in gathered]
            if len(np.unique(allp, axis=0)) != len(allp):
                raise RuntimeError("checkpoint layout: two nodes share their coordinates")

    def gather(self, local: np.ndarray) -> np.ndarray | None:
        """The canonical global array on rank 0 (None on the other ranks)."""
        if self.kind == "replicated":
            return np.asarray(local) if self.comm.rank == 0 else None
        parts = self.comm.gather(np.ascontiguousarray(local), root=0)
        if self.comm.rank != 0:
            return None
        out = np.empty(len(self._entries))
        out[self._entries] = np.concatenate(parts)
        return out

    def scatter(self, glob: np.ndarray | None) -> np.ndarray:
        """This rank's part of a canonical global array held by rank 0."""
        if self.kind == "replicated":
            return np.array(self.comm.bcast(glob if self.comm.rank == 0 else None, root=0))
        parts = None
        if self.comm.rank == 0:
            if glob.shape != (len(self._entries),):
                raise FxflexError(f"--resume: the checkpoint holds {glob.size} state entries, "
                                  f"this mesh {len(self._entries)}")
            flat = glob[self._entries]
            parts = np.split(flat, np.cumsum(self._counts)[:-1])
        return np.array(self.comm.scatter(parts, root=0))


class CheckpointWriter:
    """``on_checkpoint`` callback of :func:`fxflex.time.simulate`: writes ``path`` atomically
    every call; collective (all ranks gather, rank 0 writes)."""

    def __init__(self, path: str, layout: Layout, meta: dict, series=None,
                 last: tuple[str, int] | None = None):
        self.path = os.path.abspath(path)
        self.layout = layout
        self.meta = dict(meta)
        self.series = series
        self.written = 0
        self.seconds = 0.0
        self.last = last            # (path, step) of the last good checkpoint of this run
        self._clock = None

    def _time(self, step: int) -> float:
        if self._clock is not None:
            return self._clock["t"]
        return self.meta["settings"]["t0_s"] + step * self.meta["settings"]["dt_s"]

    def __call__(self, step: int, q, v, arrays: dict, samples: int,
                 clock: dict | None = None) -> None:
        """``clock``: a variable-step run's controller state (fxflex.time.adaptive.Clock as a
        dict: time, next step, counters), stored in meta; its time is the checkpoint's."""
        t0 = time.perf_counter()
        self._clock = clock
        glob = {"q": self.layout.gather(q), "v": self.layout.gather(v)}
        for name, arr in arrays.items():
            glob[f"scheme/{name}"] = self.layout.gather(arr)
        comm = self.layout.comm
        error = None
        if comm.rank == 0:
            error = self._write(step, samples, glob)
        error = comm.bcast(error, root=0)
        if error:
            raise OutputError(error, collective=True)
        self.last = (self.path, int(step))
        self.written += 1
        self.seconds += time.perf_counter() - t0


    def _write(self, step: int, samples: int, glob: dict) -> str | None:
        """Rank 0: write the checkpoint of ``step``; the error message if it failed."""
        meta = dict(self.meta, step=int(step), samples=int(samples), t_s=self._time(step),
                    written_at=time.strftime("%Y-%m-%d %H:%M:%S"))
        if self._clock is not None:
            meta["clock"] = self._clock
        try:
            if self.series is not None:
                size, digest = self.series.sync()
                meta["series"] = {"path": os.path.abspath(self.series.path), "bytes": size,
                                  "sha256": digest}
            _write_atomic(self.path, meta, glob)
        except OutputError as exc:
            return f"{exc}; the run stopped at step {step} (t={self._time(step):.6g} s)"
        except OSError as exc:
            if self.last is None:
                last = "no checkpoint of this run was written"
            else:
                path, at = self.last
                last = (f"the last good checkpoint is {path} at step {at} "
                        f"(t={self._time(at):.6g} s): continue with --resume {path}")
            done = f"; {self.series.abandon()}" if self.series is not None else ""
            return (f"--checkpoint: cannot write {self.path}: {exc.strerror or exc}; the run "
                    f"stopped at step {step} (t={self._time(step):.6g} s); {last}{done}")
        if self.series is not None:
            self.series.keep(size)
        return None


def _write_atomic(path: str, meta: dict, arrays: dict) -> None:
    """Write to a temporary file beside ``path``, fsync, rename over it, fsync the folder."""
    tmp = f"{path}.{os.getpid()}.tmp"
    try:
        with open(tmp, "wb") as fh:
            np.savez(fh, meta=np.array(json.dumps(meta)), **arrays)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    dirfd = os.open(os.path.dirname(path), os.O_RDONLY)
    try:
        os.fsync(dirfd)
    finally:
        os.close(dirfd)


def load_checkpoint(path: str, comm) -> tuple[dict, dict | None]:
    """(meta, arrays) of a checkpoint: meta on every rank, the arrays on rank 0 only (None
    elsewhere). An unreadable file is one FxflexError on every rank."""
    meta = arrays = error = None
    if comm.rank == 0:
        try:
            meta, arrays = _read(path)
            error = _problem(meta, arrays, path)
        except FileNotFoundError:
            error = f"--resume: file not found: {path}"
        except IsADirectoryError:
            error = f"--resume: {path} is a directory; allowed: a checkpoint file"
        except Exception as exc:        # zip, zlib, numpy and JSON each raise their own
            error = (f"--resume: {path} is not a readable fxflex checkpoint (truncated or "
                     f"another kind of file: {type(exc).__name__}: {exc})")
    error = comm.bcast(error, root=0)
    if error:
        raise FxflexError(error)
    return comm.bcast(meta, root=0), arrays


#: what every checkpoint's meta holds (FORMAT)
_META_KEYS = ("scene", "scene_hash", "settings", "step", "samples", "checkpoint", "series")


def _read(path: str) -> tuple[dict, dict]:
    with np.load(path, allow_pickle=False) as data:
        meta = json.loads(str(data["meta"]))
        arrays = {k: data[k] for k in data.files if k != "meta"}
    return meta, arrays


def _problem(meta, arrays: dict, path: str) -> str | None:
    """Why a readable npz is no checkpoint to continue from, or None."""
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        found = meta.get("format") if isinstance(meta, dict) else None
        return (f"--resume: {path} is not an fxflex checkpoint (format {found!r}, expected "
                f"{FORMAT!r})")
    missing = [k for k in _META_KEYS if k not in meta] + [k for k in ("q", "v") if k not in arrays]
    if missing:
        return f"--resume: {path} is an incomplete checkpoint (no {', '.join(missing)})"
    bad = [k for k, a in arrays.items()
           if not (np.issubdtype(a.dtype, np.number) and np.all(np.isfinite(a)))]
    if bad:
        return (f"--resume: {path} holds NaN or inf in {', '.join(bad)}: no run can continue "
                "from that state; resume from an earlier checkpoint or start again")
    return None


def _first_difference(a, b, prefix: str = "") -> str | None:
    """Dotted key of the first difference between two nested dicts."""
    for key in sorted(set(a) | set(b)):
        x, y = a.get(key), b.get(key)
        if isinstance(x, dict) and isinstance(y, dict):
            diff = _first_difference(x, y, f"{prefix}{key}.")
            if diff:
                return diff
        elif x != y:
            return f"{prefix}{key}"
    return None


def check_settings(meta: dict, scene: dict, scene_hash: str, settings: dict, path: str) -> None:
    """One FxflexError line if this run is not the one the checkpoint belongs to: the scene
    (by hash, naming the first key that differs) and each of ``settings`` (a subset may be
    checked, e.g. before the build what is known without it)."""
    if meta["scene_hash"] != scene_hash:
        key = _first_difference(meta["scene"], scene) or "scene"
        sec, _, name = key.partition(".")
        old = meta["scene"].get(sec, {}).get(name) if name else None
        new = scene.get(sec, {}).get(name) if name else None
        raise FxflexError(f"--resume: {path} belongs to scene {meta['scene_hash']}, this run's is "
                          f"{scene_hash}: {key} was {json.dumps(old)}, now {json.dumps(new)}; "
                          "resume with the same --scene/--set/--rpm/--damping options")
    for key, new in settings.items():
        old = meta["settings"].get(key)
        if new != old:
            flag = _FLAGS.get(key, key)
            raise FxflexError(f"--resume: {path} was written with {flag} {json.dumps(old)}, this "
                              f"run has {json.dumps(new)}; resume with the same run options")


#: how the settings are named in an error message
_FLAGS = {"method": "--method", "integrator": "--integrator", "dt_s": "--dt (s)",
          "t_end_s": "--t-end (s)", "t0_s": "start time (s)",
          "sample_every": "a sample every (steps, from --sample-dt)",
          "force_eval": "--force-eval", "mass": "--mass", "rho_inf": "--rho-inf",
          "tol": "--tol", "sample_dt_s": "--sample-dt (s)"}
