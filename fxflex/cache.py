"""Where fxflex keeps what it can reuse across runs: meshes, eigenmodes, invariant matrices.

The folder is ``$FXFLEX_CACHE`` if set, else ``~/.cache/fxflex``, with one subfolder per kind
(``meshes``, ``modes``, ``reduced``, ``tlf-invariants``). ``FXFLEX_NO_CACHE=1`` bypasses it: nothing
is read or written and everything is computed afresh (``FXFLEX_NO_CACHE=modes,reduced`` bypasses
only those kinds). Inside Python, ``with bypass(...)`` does the same for a block without touching
the environment (a context variable that :func:`enabled` consults besides ``FXFLEX_NO_CACHE``), so
that a bypass never leaks into other threads or child processes. ``fxflex cache info`` lists what
is stored and ``fxflex cache clear [KIND]`` deletes it.

Each entry is named by a hash of everything it depends on (:func:`entry_key`): the scene parts
that matter, mesh divisions, quadrature degree, mode count, the library versions and the source
text of the routines that produce it (:func:`code_version`), so editing any of them makes a new
entry instead of reusing a stale one. Entries are ``.npz`` archives written atomically (a
temporary file in the same folder, then ``os.replace``): a reader sees either no file or a
complete one, so concurrent runs are safe; two runs that miss at once both compute and the last
rename wins with identical content. A file that cannot be read counts as a miss.

A build never leaves an entry behind when it fails (issue 11): inside :func:`deferred` (which
:func:`fxflex.formulation.build` opens around every build) a finished temporary file is only
recorded, and becomes its entry when the block ends without an exception; an exception removes
every temporary file of the block instead. Temporary files are named after the host and the
process that writes them (``.<host>.<pid>.<name>...``), so that the temporary files of a process
that was killed (the kernel's out-of-memory killer gives no chance to clean up) are removed by the
first build of the next process on that host (:func:`sweep`, once per process and cache root: a
glob of the cache costs about a fifth of a small beam build); ``fxflex cache clear`` removes them
too.

MPI is the callers' business (this module does no communication): the eigenmodes and the reduced
models are stored in a partition-independent form by rank 0 and read by every rank, the TLF
invariant matrices (one rank's subdomain) per rank and keyed by that rank's own numbering.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import hashlib
import importlib.metadata
import importlib.util
import json
import os
import shutil
import socket
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["cache_root", "cache_dir", "enabled", "code_version", "entry_key", "load", "save",
           "publish", "usage", "clear", "bypass", "deferred", "temporary", "sweep", "KINDS"]

#: what is cached, and by whom
KINDS = {"meshes": "gmsh .msh files of the solid beam (fxflex.mesh.solid)",
         "modes": "clamped eigenmodes for FFRF/GCMS (fxflex.solid.cms)",
         "reduced": "FFRF inertia invariants and GCMS global-mode matrices (fxflex.solid)",
         "tlf-invariants": "TLF system invariant matrices, one file per rank "
                           "(fxflex.solid.tlf_invariants)"}


def cache_root() -> Path:
    return Path(os.environ.get("FXFLEX_CACHE") or Path.home() / ".cache" / "fxflex")


#: the kinds barred by the innermost open :func:`bypass` block (None: no block open; ALL: every
#: kind); a context variable, not ``os.environ``, so that a bypass stays in this process, thread
#: and block
_BYPASSED: contextvars.ContextVar[frozenset[str] | None] = contextvars.ContextVar(
    "fxflex_cache_bypassed", default=None)
#: what :func:`bypass` with no kind named bars
_ALL = frozenset(KINDS)


def enabled(kind: str | None = None) -> bool:
    """Whether ``kind`` may be read and written (no kind: whether every kind may).

    Barred by an open :func:`bypass` block naming it (or naming none), or by ``FXFLEX_NO_CACHE``:
    unset, empty or 0 allows all, a comma-separated list of kinds (``modes,reduced``) bars those,
    anything else (``1``) bars all. The environment variable is how a command line or a child
    process is told; :func:`bypass` is how Python code is."""
    barred = _BYPASSED.get()
    if barred:
        if kind is None or kind in barred:
            return False
    value = os.environ.get("FXFLEX_NO_CACHE", "").strip()
    if value in ("", "0"):
        return True
    barred = {v.strip() for v in value.split(",")}
    if not barred <= set(KINDS):
        return False
    return kind is not None and kind not in barred


@contextlib.contextmanager
def bypass(*kinds: str):
    """``with bypass("modes"):`` -- those kinds (all if none named) neither read nor written
    inside the block (benchmarks of cold builds). Blocks nest (an inner block bars its kinds
    besides the outer block's). ``os.environ`` is left alone: the bypass holds for this
    process's code inside the block only; a child process started there is told with
    ``FXFLEX_NO_CACHE`` in its environment."""
    unknown = [k for k in kinds if k not in KINDS]
    if unknown:
        raise ValueError(f"cache.bypass: unknown kind(s) {', '.join(map(repr, unknown))}; "
                         f"allowed: {', '.join(KINDS)}")
    outer = _BYPASSED.get() or frozenset()
    token = _BYPASSED.set(outer | (frozenset(kinds) if kinds else _ALL))
    try:
        yield
    finally:
        _BYPASSED.reset(token)


#: the (temporary file, entry) pairs published inside the innermost open :func:`deferred` block;
#: a context variable rather than an argument so that every writer (meshes, modes, reduced models,
#: invariants) joins the build's block without threading it through the formulations
_PENDING: contextvars.ContextVar[list[tuple[Path, Path]] | None] = contextvars.ContextVar(
    "fxflex_cache_pending", default=None)


#: the cache roots this process has swept (:func:`deferred`)
_SWEPT: set[Path] = set()


@contextlib.contextmanager
def deferred():
    """``with deferred():`` -- entries published inside the block appear only if it ends without
    an exception; otherwise their temporary files are deleted and the cache is as before. A block
    opened inside another joins it (the outer block decides). Also sweeps the temporary files of
    dead processes (:func:`sweep`) when the first outermost block of this process opens (on
    each cache root)."""
    if _PENDING.get() is not None:
        yield
        return
    root = cache_root()
    if root not in _SWEPT:              # once per process and cache: a glob of the whole cache
        sweep()                         # costs ~1 ms, a beam build 2-5 ms
        _SWEPT.add(root)
    pending: list[tuple[Path, Path]] = []
    token = _PENDING.set(pending)
    try:
        yield
    except BaseException:
        for tmp, _ in pending:
            _remove(tmp)
        raise
    else:
        for i, (tmp, path) in enumerate(pending):
            try:
                os.replace(tmp, path)
            except OSError:             # not committed: only costs the next run time
                for rest, _ in pending[i:]:
                    _remove(rest)
                break
    finally:
        _PENDING.reset(token)


def _remove(path: Path) -> None:
    with contextlib.suppress(OSError):
        os.unlink(path)


def temporary(folder: Path, name: str, suffix: str = ".tmp") -> Path:
    """A new empty temporary file in ``folder`` for entry ``name``, named after this host and
    process (how :func:`sweep` knows whose it is)."""
    fd, tmp = tempfile.mkstemp(prefix=f".{socket.gethostname()}.{os.getpid()}.{name}.",
                               suffix=suffix, dir=folder)
    os.close(fd)
    return Path(tmp)


def sweep() -> list[Path]:
    """Delete the temporary files left in the cache by processes of this host that no longer
    run (a build killed before it could clean up); returns what was deleted."""
    root, host = cache_root(), socket.gethostname()
    removed = []
    if not root.is_dir():
        return removed
    for tmp in root.glob(f"*/.{host}.*"):
        pid = tmp.name[len(host) + 2:].split(".", 1)[0]
        if pid.isdigit() and not _alive(int(pid)):
            _remove(tmp)
            removed.append(tmp)
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:             # someone else's process
        return True
    return True


def cache_dir(kind: str) -> Path:
    path = cache_root() / kind
    path.mkdir(parents=True, exist_ok=True)
    return path


def code_version(*modules: str) -> str:
    """Hash of the source text of ``modules`` (dotted names), this module and the versions of
    the numerical libraries: what an entry's producing routine was."""
    h = hashlib.sha256()
    for name in sorted({*modules, __name__}):
        spec = importlib.util.find_spec(name)
        h.update(name.encode())
        h.update(Path(spec.origin).read_bytes())
    h.update(_library_versions().encode())
    return h.hexdigest()[:16]


@functools.cache
def _library_versions() -> str:
    """Installed versions from the package metadata (importing the libraries to ask them would
    cost what a cache hit saves), read once per process (the libraries it has loaded do not
    change; reading the metadata was 9 ms of every key, a third of a small solid's build)."""
    versions = {}
    for dist in ("numpy", "scipy", "fenics-dolfinx", "fenics-basix", "fenics-ffcx", "fenics-ufl",
                 "petsc4py", "slepc4py"):
        try:
            versions[dist] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            versions[dist] = None
    return json.dumps(versions, sort_keys=True)


def entry_key(parts: dict) -> str:
    """24 hex digits of the SHA-256 of ``parts`` (JSON, keys sorted; tuples as lists)."""
    text = json.dumps(parts, sort_keys=True, separators=(",", ":"), default=_plain)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def _plain(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.integer, np.floating)):
        return obj.item()
    raise TypeError(f"entry_key: cannot hash {type(obj).__name__}")


def _path(kind: str, key: str) -> Path:
    return cache_root() / kind / f"{key}.npz"


def load(kind: str, key: str) -> dict[str, np.ndarray] | None:
    """The arrays of entry ``key``, or None (absent, unreadable, or the cache is off)."""
    if not enabled(kind):
        return None
    path = _path(kind, key)
    try:
        with np.load(path, allow_pickle=False) as data:
            return {name: data[name] for name in data.files}
    except (OSError, ValueError, EOFError, KeyError):
        return None


def save(kind: str, key: str, arrays: dict) -> Path | None:
    """Write entry ``key`` atomically; returns its path (None when the cache is off or the
    folder is not writable: a cache that cannot be written only costs time)."""
    if not enabled(kind):
        return None
    try:
        tmp = temporary(cache_dir(kind), key)
        try:
            with open(tmp, "wb") as fh:
                np.savez(fh, **{k: np.asarray(v) for k, v in arrays.items()})
            publish(tmp, _path(kind, key))
        except BaseException:
            _remove(tmp)
            raise
    except OSError:
        return None
    return _path(kind, key)


def publish(tmp: str | Path, path: Path) -> None:
    """Make a finished temporary file the entry ``path`` in one step (readable by all, as a
    shared cache folder needs: mkstemp creates files private to their owner) -- at once, or,
    inside :func:`deferred`, when the block ends well."""
    os.chmod(tmp, 0o644)
    pending = _PENDING.get()
    if pending is None:
        os.replace(tmp, path)
    else:
        pending.append((Path(tmp), Path(path)))


def usage() -> dict[str, dict]:
    """{kind: {"files", "bytes"}} for every folder in the cache."""
    root = cache_root()
    out = {}
    if root.is_dir():
        for folder in sorted(p for p in root.iterdir() if p.is_dir()):
            files = [f for f in folder.iterdir() if f.is_file() and not f.name.startswith(".")]
            out[folder.name] = {"files": len(files), "bytes": sum(f.stat().st_size for f in files)}
    return out


def clear(kind: str | None = None) -> dict[str, dict]:
    """Delete one kind's folder (or the whole cache); returns what was there."""
    before = usage()
    root = cache_root()
    targets = [root / kind] if kind else [root / k for k in before]
    for path in targets:
        shutil.rmtree(path, ignore_errors=True)
    return {k: v for k, v in before.items() if kind in (None, k)}
