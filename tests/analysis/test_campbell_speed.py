"""TLF Campbell sweeps (issue 16, :mod:`fxflex.solid.tlf_sweep`): what one speed hands the next --
the SolidModel, the equilibria as Newton's start, the mode vectors as SLEPc's initial space, the
LDL^T of a symmetric K -- leaves every speed's equilibrium within the Newton tolerance and its
roots within the eigensolver's tolerance of a cold build of that speed; and the ElastoDyn export
of TLF on the default mesh."""

import json
import subprocess
import sys

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.analysis.modes import campbell_tracked, modes_of, speed_builder
from fxflex.formulation import BuildOptions, build, rescene
from fxflex.numerics import petsc as pep
from fxflex.scene import load_scene
from fxflex.solid.tlf_sweep import SpeedSweep

COMM = MPI.COMM_WORLD
#: the coarse blade of docs/stability.md's TLF veering (the default twisted blade, 20 x 4 x 2)
SMALL = ["mesh.solid=[20,4,2]"]
#: the order the tracker visits speeds in: a requested one, a jump of more than one continuation
#: stage (Omega^2 from 0 to 10000 rpm: staged from the 0 rpm equilibrium), then two bisections
#: (predicted from the two nearest equilibria)
VISITS = (0.0, 10000.0, 5000.0, 7500.0)


@pytest.fixture(scope="module")
def cached(tmp_path_factory):
    """One cache folder for the module, the same on every rank (as tests/test_at.py)."""
    folder = COMM.bcast(str(tmp_path_factory.mktemp("cache")) if COMM.rank == 0 else None)
    with pytest.MonkeyPatch.context() as env:
        env.setenv("FXFLEX_CACHE", folder)
        env.delenv("FXFLEX_NO_CACHE", raising=False)
        yield


def _norm(v: np.ndarray) -> float:
    return float(np.sqrt(COMM.allreduce(float(np.dot(v, v)))))


@pytest.mark.parametrize("model", ["relative", "absolute"])
def test_sweep_members_equal_cold_builds(cached, gathered_dense, model):
    """Each member of a sweep against a fresh build of its speed. Equilibrium: both iterates
    leave residuals r_w, r_c (Newton's last, at the iterate returned), so to first order
    ||U_w - U_c|| <= (r_w + r_c) / sigma_min(J), J Newton's Jacobian on the free coordinates (the
    linearisation's K with the consistent mass; the remainder is quadratic in residuals of
    1e-10 of the load, so twice the bound holds it). That moves the roots by about the same
    relative amount, below the PEP's tolerance; the roots then agree to 10 x pep.TOL as in
    tests/analysis/test_modes_mpi.py (both sides converged to TOL on the shift-inverted problem,
    one by LU, the other by LDL^T and from another start)."""
    options = BuildOptions(mass="consistent")
    scene = load_scene(overrides=SMALL + [f'damping.model="{model}"'])
    sweep = SpeedSweep(scene, COMM, options)
    for rpm in VISITS:
        warm = sweep.at(rpm)
        cold = build("tlf", rescene(scene, rpm=rpm), COMM, options)
        assert warm.model.mesh is sweep.model.mesh and warm.model.scene == cold.scene
        sw, sc = warm.steady_state(), cold.steady_state()
        assert sw.converged and sc.converged and sweep.cold_fallbacks == 0
        lin = cold.linearise(sc)
        try:
            sigma = np.linalg.svd(gathered_dense(lin.K, COMM), compute_uv=False)[-1]
        finally:
            lin.destroy()
        bound = 2.0 * (sw.residuals[-1] + sc.residuals[-1]) / sigma
        size = _norm(sc.q)
        assert _norm(sw.q - sc.q) <= bound
        if rpm > 0.0:
            assert bound <= pep.TOL * size          # the equilibria agree beyond the PEP's tol
        if rpm == VISITS[-1]:                       # predicted: fewer steps than from rest
            assert sw.iterations < sc.iterations
        mw, mc = modes_of(warm, 8), modes_of(cold, 8)
        np.testing.assert_allclose(mw.eigenvalues, mc.eigenvalues, rtol=10 * pep.TOL, atol=0)
        assert mw.labels == mc.labels and mw.stable == mc.stable
    assert [w for w, _ in sweep.equilibria] == [rescene(scene, rpm=r).rotation.omega
                                                for r in VISITS]


def test_tracked_campbell_equals_the_cold_one(cached):
    """``fxflex modes --campbell``'s tracking over a sweep and over cold builds at every speed:
    the same speeds (the refinements are decided by MACs of the same shapes), the same branches,
    their roots to 10 x pep.TOL as above."""
    scene = load_scene(overrides=SMALL)
    speeds = np.linspace(0.0, 12000.0, 4)

    def cold(rpm):
        return build("tlf", rescene(scene, rpm=rpm), COMM)

    warm = campbell_tracked(speed_builder("tlf", scene, COMM), speeds, 6, "tlf")
    ref = campbell_tracked(cold, speeds, 6, "tlf")
    np.testing.assert_array_equal(warm.rpm, ref.rpm)
    assert [b.label for b in warm.branches] == [b.label for b in ref.branches]
    for a, b in zip(warm.branches, ref.branches):
        assert a.directions == b.directions
        np.testing.assert_allclose(a.eigenvalues, b.eigenvalues, rtol=10 * pep.TOL, atol=0)
        np.testing.assert_allclose(a.mac, b.mac, atol=1e-6)


def test_failed_warm_start_falls_back_to_the_cold_solve(cached, distributed_rtol):
    """A start Newton cannot use (not finite) is dropped: the cold continuation's equilibrium,
    bit for bit on one rank."""
    scene = load_scene(overrides=SMALL)
    sweep = SpeedSweep(scene, COMM)
    form = sweep.at(8000.0)
    omega = form.scene.rotation.omega
    sweep.equilibria.append((omega, np.full(form.model.n_owned, np.nan)))
    st = form.steady_state()
    fresh = build("tlf", form.scene, COMM)
    ref = fresh.steady_state()
    assert st.converged and sweep.cold_fallbacks == 1
    np.testing.assert_allclose(st.tip, ref.tip, rtol=distributed_rtol(fresh, ref), atol=0.0)


@pytest.mark.paper
@pytest.mark.serial
def test_elastodyn_export_of_tlf_on_the_default_mesh(tmp_path):
    """``fxflex modes --method tlf --elastodyn`` on the default scene (100 x 12 x 6 Q1, the
    twisted tapered blade at 1000 rpm): every shape's coefficients sum to 1 to the KKT solve's
    round-off (tests/analysis/test_elastodyn.py), the file is written, and flap 1 is fitted by
    the x^2..x^6 polynomial to within 10 x the bound the closed-form cantilever's first mode
    meets (1e-5, tests/analysis/test_elastodyn.py): taper and twist keep it a smooth bending
    shape (measured 1.9e-5, docs/stability.md). Serial: it checks the command's output."""
    path = tmp_path / "blade.dat"
    r = subprocess.run([sys.executable, "-m", "fxflex", "modes", "--method", "tlf",
                        "--elastodyn", str(path), "--json"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    shapes = d["elastodyn"]["shapes"]
    assert set(shapes) == {"BldFl1Sh", "BldFl2Sh", "BldEdgSh"} and path.is_file()
    for shape in shapes.values():
        c = np.array(shape["coefficients"])
        assert abs(np.sum(c) - 1.0) <= 1e-12 * np.sum(np.abs(c))
    flap1 = shapes["BldFl1Sh"]
    assert d["labels"][flap1["mode"] - 1] == "out-of-plane"
    assert flap1["residual"] < 1e-4
