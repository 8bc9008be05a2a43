"""A build that fails leaves no cache entry behind (issue 11): deferred entries, the temporary
files of killed processes, and out-of-memory failures reported as one line."""

import os
import socket
import subprocess
import sys

import numpy as np
import pytest

from fxflex import cache
from fxflex.formulation import build
from fxflex.scene import Scene

pytestmark = pytest.mark.serial

SMALL = {"mesh.solid": (4, 2, 2), "reduction.ffrf_modes": 4, "reduction.gcms_modes": 6}


def files(folder):
    """Every file in the cache folder, hidden temporary files included."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


def test_entries_saved_in_a_deferred_block_appear_when_it_ends(folder):
    with cache.deferred():
        cache.save("modes", "k1", {"a": np.arange(3.0)})
        with cache.deferred():                          # a nested block joins the outer one
            cache.save("reduced", "k2", {"a": np.ones(2)})
        assert cache.load("modes", "k1") is None and cache.load("reduced", "k2") is None
    assert files(folder) == ["modes/k1.npz", "reduced/k2.npz"]
    assert np.array_equal(cache.load("modes", "k1")["a"], np.arange(3.0))


def test_an_exception_in_a_deferred_block_leaves_the_cache_as_it_was(folder):
    cache.save("modes", "old", {"a": np.zeros(1)})
    with pytest.raises(RuntimeError, match="later stage"):
        with cache.deferred():
            cache.save("modes", "k1", {"a": np.arange(3.0)})
            with cache.deferred():
                cache.save("reduced", "k2", {"a": np.ones(2)})
            raise RuntimeError("a later stage failed")
    assert files(folder) == ["modes/old.npz"]
    cache.save("modes", "k3", {"a": np.zeros(1)})       # outside a block: at once, as before
    assert files(folder) == ["modes/k3.npz", "modes/old.npz"]


def test_temporary_files_of_dead_processes_are_swept(folder):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    (folder / "meshes").mkdir()
    host = socket.gethostname()
    left = folder / "meshes" / f".{host}.{dead.stdout.strip()}.beam-abc.x1.msh"
    left.write_bytes(b"half a mesh")
    mine = cache.temporary(folder / "meshes", "beam-def", suffix=".msh")
    other_host = folder / "meshes" / f".not-{host}.1.beam-ghi.x2.msh"
    other_host.write_bytes(b"")
    with cache.deferred():
        pass
    assert not left.exists() and mine.exists() and other_host.exists()


_original: dict = {}


def _fail_after(monkeypatch, target: str, exc: BaseException):
    """Make the method ``target`` (dotted path) raise ``exc`` once it has done its work."""
    import importlib

    module_name, cls_name, attr = target.rsplit(".", 2)
    cls = getattr(importlib.import_module(module_name), cls_name)
    original = getattr(cls, attr)

    def failing(self, *args, **kwargs):
        original(self, *args, **kwargs)
        raise exc

    _original[target] = original
    monkeypatch.setattr(cls, attr, failing)


@pytest.mark.parametrize("method, target, kinds", [
    ("tlf", "fxflex.solid.model.SolidModel.__init__", {"meshes"}),
    ("ffrf", "fxflex.solid.ffrf.FFRF._build_operators", {"meshes", "modes", "reduced"})])
def test_a_build_failing_after_writing_entries_leaves_none(folder, monkeypatch, method, target,
                                                            kinds):
    """The entries were fine (the same build keeps them when it succeeds); a later stage failed."""
    from mpi4py import MPI

    scene = Scene().replace(**SMALL)
    _fail_after(monkeypatch, target, RuntimeError("boom"))
    with pytest.raises(RuntimeError, match="boom"):
        build(method, scene, MPI.COMM_WORLD)
    assert files(folder) == []
    monkeypatch.setattr(target, _original[target])
    build(method, scene, MPI.COMM_WORLD)
    assert {f.split("/")[0] for f in files(folder)} == kinds
    assert not any(os.path.basename(f).startswith(".") for f in files(folder))


def _petsc_out_of_memory():
    from petsc4py import PETSc

    return PETSc.Error(55)                      # PETSC_ERR_MEM


@pytest.mark.parametrize("error", [lambda: MemoryError("Unable to allocate 1.3 GiB"),
                                   _petsc_out_of_memory], ids=["numpy", "petsc"])
def test_memory_error_mid_build_is_one_line_and_leaves_no_entry(folder, monkeypatch, capsys,
                                                                 error):
    from fxflex.cli import main

    _fail_after(monkeypatch, "fxflex.solid.model.SolidModel.__init__", error())
    status = main(["steady", "--method", "tlf", "--set", "mesh.solid=[4,2,2]", "--json"])
    out, err = capsys.readouterr()
    assert status == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("fxflex: error: out of memory"), err
    assert files(folder) == []
