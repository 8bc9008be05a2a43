"""Disk caches of the solid methods: clamped eigenmodes, FFRF/GCMS projections, TLF invariant
matrices. A hit returns exactly what the miss computed; changing any keyed input misses; the
eigenmode entries do not depend on the number of ranks."""

from types import SimpleNamespace

import numpy as np
import pytest
from mpi4py import MPI

from fxflex import cache
from fxflex.formulation import build
from fxflex.mesh.solid import mesh_key
from fxflex.scene import load_scene
from fxflex.solid.cms import clamped_modes, modes_key
from fxflex.solid.tlf_invariants import InvariantForce, invariant_key
from fxflex.solid.model import SolidModel
from fxflex.solid.reduction import reduced_key

SELF, COMM = MPI.COMM_SELF, MPI.COMM_WORLD
SCENE = load_scene(overrides=["mesh.solid=[8,2,2]", "reduction.ffrf_modes=6",
                              "reduction.gcms_modes=18"])


@pytest.fixture
def folder(tmp_path, monkeypatch):
    path = COMM.bcast(str(tmp_path), root=0)        # one folder for every rank
    monkeypatch.setenv("FXFLEX_CACHE", path)
    monkeypatch.delenv("FXFLEX_NO_CACHE", raising=False)
    return path


def _variants(scene):
    """One change of each keyed scene part."""
    return {"geometry": scene.replace(**{"geometry.twist_deg": -30.0}),
            "divisions": scene.replace(**{"mesh.solid": (8, 2, 4)}),
            "E": scene.replace(**{"material.E": 200e9}),
            "nu": scene.replace(**{"material.nu": 0.3}),
            "rho": scene.replace(**{"material.rho": 7800.0})}


@pytest.mark.serial
def test_modes_hit_is_identical_and_every_keyed_input_misses(folder, monkeypatch, eig):
    model = SolidModel(SCENE, SELF)
    a, b = clamped_modes(model, 6), clamped_modes(model, 6)
    assert not a.from_cache and b.from_cache and "eigensolve" in a.timings
    for name in ("omega2", "vectors", "errors"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name

    def key(scene=SCENE, count=6, tol=1e-12, degree=2):
        mesh = SimpleNamespace(key=mesh_key(scene.geometry, scene.mesh.solid))
        return modes_key(SimpleNamespace(scene=scene, solid_mesh=mesh, quadrature_degree=degree,
                                         degree=1), count, tol)

    base = modes_key(model, 6, 1e-12)
    assert key() == base
    keys = {name: key(scene) for name, scene in _variants(SCENE).items()}
    keys.update(count=key(count=7), tol=key(tol=1e-10), quadrature=key(degree=3))
    with monkeypatch.context() as patch:           # (undo only this, not the cache folder)
        patch.setattr(cache, "code_version", lambda *modules: "edited")
        keys["code"] = key()
    assert base not in keys.values() and len(set(keys.values())) == len(keys)
    other = SolidModel(SCENE.replace(**{"material.E": 200e9}), SELF)
    c = clamped_modes(other, 6)
    # K is linear in E: the eigenvalues scale by 200 / 210, each solve to its certified radius
    assert not c.from_cache
    assert np.all(np.abs(c.omega2 - a.omega2 * 200 / 210)
                  <= eig.radii(other, c) + eig.radii(model, a) * 200 / 210)


@pytest.mark.serial
@pytest.mark.parametrize("method", ["ffrf", "gcms"])
def test_reduced_hit_needs_no_mesh_and_is_identical(folder, method):
    a, b = build(method, SCENE, SELF), build(method, SCENE, SELF)
    assert "eigenmodes" in a.timings and "cache_load" not in a.timings
    assert "cache_load" in b.timings and b._model is None and b._modes is None   # no mesh built
    assert b.dof == a.dof and np.array_equal(b.steady_state().tip, a.steady_state().tip)
    # speed and damping are not keyed: another one hits and agrees with a fresh build
    sc = SCENE.replace(**{"rotation.rpm": 5000.0, "damping.c": 100.0,
                          "damping.model": "absolute"})
    c = build(method, sc, SELF)
    with cache.bypass():
        d = build(method, sc, SELF)
    assert "cache_load" in c.timings and "cache_load" not in d.timings
    # a cache hit and a fresh build of the same projections: the same linear solve on matrices equal
    # to round-off
    assert np.allclose(c.steady_state().tip, d.steady_state().tip, rtol=1e-12, atol=0)
    # what --fields needs is built on demand after a hit (the modes from their own cache)
    basis, _ = b.nodal_basis()
    assert b.modes.from_cache and basis.shape == (b.model.n_owned, b.dof)
    # every keyed input changes the key
    count = 6
    extra = {"gram_tol": SCENE.reduction.gcms_gram_tol} if method == "gcms" else {}
    key = reduced_key(SCENE, method, count, **extra)
    changed = [reduced_key(s, method, count, **extra) for s in _variants(SCENE).values()]
    changed += [reduced_key(SCENE.replace(**{"load.line_load": -1000.0}), method, count, **extra),
                reduced_key(SCENE.replace(**{"load.tip_force": (0.0, 1.0, 0.0)}), method, count,
                            **extra),
                reduced_key(SCENE, method, count + 1, **extra)]
    if method == "gcms":
        changed.append(reduced_key(SCENE, method, count, gram_tol=1e-8))
    assert key not in changed and len(set(changed)) == len(changed)
    assert key == reduced_key(sc.replace(**{"load.ramp_time": 1e-3}), method, count, **extra)


@pytest.mark.serial
def test_tlf_invariants_hit_is_identical(folder):
    model = SolidModel(SCENE, SELF)
    a, b = InvariantForce(model), InvariantForce(model)
    assert not a.from_cache and b.from_cache
    u = 1e-3 * np.random.default_rng(0).standard_normal(a.n)
    fa, fb = np.empty(a.n), np.empty(a.n)
    a.apply(u, fa)
    b.apply(u, fb)
    assert np.abs(fa).max() > 0 and np.array_equal(fa, fb)
    assert a.nnz == b.nnz and a.nnz_full == b.nnz_full
    other = SolidModel(SCENE.replace(**{"material.nu": 0.3}), SELF)
    assert invariant_key(other) != invariant_key(model)
    assert not InvariantForce(other).from_cache
    finer = SolidModel(SCENE.replace(**{"mesh.solid": (10, 2, 2)}), SELF)
    assert invariant_key(finer) != invariant_key(model)


@pytest.mark.mpi
def test_modes_written_on_one_rank_serve_two_and_back(folder, eig):
    """1 rank writes, 2 ranks read (and the reverse): the rows each rank gets match a fresh
    solve on its partition to round-off."""
    if COMM.rank == 0:
        clamped_modes(SolidModel(SCENE, SELF), 6)                  # written by one rank
    COMM.Barrier()
    model = SolidModel(SCENE, COMM)
    read = clamped_modes(model, 6)
    fresh = clamped_modes(model, 6, use_cache=False)
    assert read.from_cache and not fresh.from_cache
    assert read.vectors.shape == fresh.vectors.shape and read.vectors.shape[0] < 3 * 9 * 3 * 3
    scale = COMM.allreduce(np.abs(fresh.vectors).max(), op=MPI.MAX)
    assert COMM.allreduce(np.abs(read.vectors - fresh.vectors).max(), op=MPI.MAX) < 1e-8 * scale
    # the cached serial solve to its certified radius (its rows whole on every rank, from the
    # cache); the distributed one, the same algorithm and tolerance, taken to be as accurate
    whole = SolidModel(SCENE, SELF)
    assert np.all(np.abs(read.omega2 - fresh.omega2)
                  <= 2 * eig.radii(whole, clamped_modes(whole, 6)))
    written = clamped_modes(model, 7)                                # written by two ranks
    assert not written.from_cache
    if COMM.rank == 0:
        serial = SolidModel(SCENE, SELF)
        back, again = clamped_modes(serial, 7), clamped_modes(serial, 7, use_cache=False)
        assert back.from_cache
        assert np.abs(back.vectors - again.vectors).max() < 1e-8 * np.abs(again.vectors).max()
    COMM.Barrier()


@pytest.mark.mpi
def test_reduced_model_written_on_one_rank_serves_two(folder):
    serial = build("ffrf", SCENE, SELF).steady_state().tip if COMM.rank == 0 else None
    serial = COMM.bcast(serial, root=0)
    read = build("ffrf", SCENE, COMM)
    with cache.bypass():
        fresh = build("ffrf", SCENE, COMM)
    assert "cache_load" in read.timings and "cache_load" not in fresh.timings
    assert np.array_equal(read.steady_state().tip, serial)
    # a reduced steady state from a distributed and a serial eigensolve: the modes agree to their
    # certified radii, the projected solve to ~ n eps cond
    assert np.allclose(fresh.steady_state().tip, serial, rtol=1e-9, atol=0)
