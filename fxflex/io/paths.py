"""Output paths checked before anything is built or written.

A command names its outputs (files it will create or replace, folders it will write into) and
its inputs (the scene, the checkpoint it resumes). :func:`check_paths` refuses, with one line
naming the flag, the path and the reason, every output that cannot succeed or would destroy
data: an empty name, a directory or device where a file goes, a file where a folder goes, a
missing or unwritable folder, a wrong suffix, two outputs that are the same file, an output that
is one of the inputs. Writability is probed by creating and removing a file in the folder,
which is the only test that also sees read-only mounts, immutable folders and ``/proc``. The
check runs on rank 0 and its verdict is broadcast, so every rank raises the same error together.
"""

from __future__ import annotations

import os
import stat
import tempfile
from dataclasses import dataclass

from fxflex.errors import FxflexError

__all__ = ["Output", "check_paths"]


@dataclass(frozen=True)
class Output:
    """One output of a command: ``flag`` names it in messages; ``folder`` for a directory the
    command writes into; ``suffix`` the ending a file must have; ``beside`` the files written
    next to it (an XDMF file's HDF5 data), checked for clashes like the file itself."""

    flag: str
    path: str | None
    folder: bool = False
    suffix: str | None = None
    beside: tuple[str, ...] = ()


def check_paths(comm, outputs: list[Output], inputs: dict[str, str | None] | None = None,
                may_replace: tuple[tuple[str, str], ...] = ()) -> None:
    """Raise one FxflexError on every rank if an output cannot be written safely.

    ``inputs`` maps a flag to the file it reads; ``may_replace`` lists (output flag, input flag)
    pairs allowed to be the same file (a resumed run replaces its own checkpoint)."""
    error = None
    if comm.rank == 0:
        error = _first_problem(outputs, dict(inputs or {}), set(may_replace))
    error = comm.bcast(error, root=0)
    if error:
        raise FxflexError(error)


def _first_problem(outputs, inputs, may_replace) -> str | None:
    given = [o for o in outputs if o.path is not None]
    for out in given:
        problem = _folder_problem(out) if out.folder else _file_problem(out)
        if problem:
            return problem
    files = [(o.flag, p) for o in given if not o.folder for p in (o.path, *o.beside)]
    for i, (flag, path) in enumerate(files):
        for other_flag, other in files[:i]:
            if _same_file(path, other):
                return (f"{other_flag} and {flag}: both name {path}; allowed: a different file "
                        "for each output")
        for in_flag, source in inputs.items():
            if source and (flag, in_flag) not in may_replace and _same_file(path, source):
                return (f"{flag}: {path} is the {in_flag} file this command reads; it would be "
                        "overwritten; allowed: another file name")
    return None


def _file_problem(out: Output) -> str | None:
    flag, path = out.flag, out.path
    if not path.strip():
        return f"{flag}: empty file name; allowed: a file name"
    if out.suffix and not path.lower().endswith(out.suffix):
        return f"{flag}: {path} does not end in {out.suffix}; allowed: FILE{out.suffix}"
    if os.path.isdir(path):
        return f"{flag}: {path} is a directory; allowed: a file name"
    if os.path.lexists(path) and not stat.S_ISREG(os.stat(path).st_mode):
        return (f"{flag}: {path} is not a regular file (a device, pipe or socket); allowed: a "
                "regular file")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        what = "is not a directory" if os.path.exists(folder) else "does not exist"
        return f"{flag}: directory {what}: {folder}"
    return _probe(flag, folder) or _probe_file(flag, path)


def _folder_problem(out: Output) -> str | None:
    flag, path = out.flag, out.path
    if not path.strip():
        return f"{flag}: empty directory name; allowed: a directory"
    existing = os.path.abspath(path)
    while not os.path.exists(existing):
        existing = os.path.dirname(existing)
    if not os.path.isdir(existing):
        return (f"{flag}: {existing} is not a directory (needed for {path}); allowed: a "
                "directory or a name not yet taken")
    return _probe(flag, existing)


def _probe(flag: str, folder: str) -> str | None:
    """The reason a new file cannot be created in ``folder``, or None."""
    try:
        fd, name = tempfile.mkstemp(prefix=".fxflex-probe-", dir=folder)
        os.close(fd)
        os.unlink(name)
    except OSError as exc:
        return f"{flag}: cannot write into {folder}: {exc.strerror or exc}"
    return None


def _probe_file(flag: str, path: str) -> str | None:
    """The reason an existing file cannot be opened for writing (without changing it), or None."""
    if not os.path.exists(path):
        return None
    try:
        with open(path, "ab"):
            pass
    except OSError as exc:
        return f"{flag}: cannot write {path}: {exc.strerror or exc}"
    return None


def _same_file(a: str, b: str) -> bool:
    """Same file: by inode when both exist (hard links, symlinks), else by normalised path."""
    if os.path.exists(a) and os.path.exists(b):
        return os.path.samefile(a, b)
    return os.path.normcase(os.path.realpath(a)) == os.path.normcase(os.path.realpath(b))
