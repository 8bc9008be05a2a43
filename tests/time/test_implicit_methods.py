"""Generalised-alpha with each of the six formulations: the Implicit interface (force, mass, factor
of the tangents) against finite differences, the paper's transients reproduced within 1 % of the
peak at 10 times the paper's step and at the default step, factor reuse, and allocation-free
steps. (Two ranks against one: tests/solid/test_tlf_mpi.py.)"""

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.bench.implicit import compare, reference
from fxflex.bench.reduced import ReducedFamily
from fxflex.formulation import (METHODS, PAPER_INTEGRATION, BuildOptions, Implicit, build,
                                implicit_step)
from fxflex.scene import load_scene
from fxflex.time import GeneralizedAlpha, simulate

COMM = MPI.COMM_WORLD

#: scenes that build in about a second, with a tip force and spin-up so every term is alive
SMALL = {"ffrf": ["mesh.solid=[10,2,2]", "reduction.ffrf_modes=12"],
         "gcms": ["mesh.solid=[10,2,2]", "reduction.gcms_modes=36"],
         "tlf": ["mesh.solid=[6,2,2]"], "lebb": [], "nebb": [],
         "ancf": ["mesh.beam_elements=4"]}
LIVE = ["load.tip_force=[300.0, -200.0, 500.0]", "rotation.profile=\"spin-up\"",
        "rotation.spinup_time=0.02", "rotation.rpm=3000", "damping.c=2e4"]


def small(method, *extra, mass=None):
    scene = load_scene(overrides=SMALL[method] + list(extra))
    return build(method, scene, COMM, BuildOptions(mass=mass, need_steady=False))


def state_at(form, t):
    """A state of the running transient at time t (coarse implicit steps: any state will do)."""
    q, v = form.initial_state()
    simulate(form, "generalized-alpha", t / 20, t, sample_every=20, state=(q, v))
    return q, v


def free_mask(form, q, v):
    """True on free coordinates: where constrain() does not overwrite a perturbation."""
    qq, vv = q.copy() + 1.0, v.copy()
    form.constrain(0.0, qq, vv)
    return qq == q + 1.0


# On 2 ranks the TLF cases miss the factor check by 0.34 (the difference construction below works
# on each rank's owned rows, which is not yet rank-independent), while a TLF generalized-alpha run
# on 2 ranks equals the serial one to 1e-10 with the same Newton iterations: serial until the
# test is made distributed (issue 11 note)
_SERIAL_TLF = pytest.mark.serial
CASES = [pytest.param(m, None, marks=_SERIAL_TLF) if m == "tlf" else (m, None) for m in METHODS] + [
    pytest.param("tlf", "consistent", marks=_SERIAL_TLF), ("ancf-absolute", None),
    pytest.param("tlf-absolute", None, marks=_SERIAL_TLF), ("nebb-locking-free", None),
    ("ancf-locking-free", None), ("nebb-locking-free-element", None)]


@pytest.mark.parametrize("method,mass", CASES)
def test_force_mass_and_factor_agree_with_finite_differences(method, mass):
    """At a state of a spin-up transient with a tip force and heavy damping (phi = 0.8 rad,
    phi' = 218 rad/s, every term alive): M acceleration = F on the free rows, and the factor
    solves S x = r for S x = m M x + c C_t x + k K_t x with C_t x, K_t x the differences of -F
    along x, for a mass-dominated (the integrator's at h = 10 us) and a stiffness-dominated
    (h = 1 ms) matrix. TLF leaves out its skew relative-damping term k c/rho phi' M S_d, relative
    size up to 2 k c/rho phi' / m (3e-4 here at h = 1 ms), which the tolerance allows for."""
    # measured otherwise: 1e-16 to 5e-7; leaving out NEBB's geometric stiffness gives 0.4, ANCF's
    # relative-damping dQ_d/de 2e-4
    name, extra = method.split("-")[0], []
    if method.endswith("absolute"):
        extra = ["damping.model=\"absolute\""]
    if "locking-free" in method:             # mesh.beam_variant (issue 13): the same interface
        extra = ["mesh.beam_variant=\"locking-free\""]
    form = small(name, *LIVE, *extra, mass=mass)
    if method.endswith("element"):
        form.force_eval = "element"
    assert isinstance(form, Implicit)
    t = 0.012
    q, v = state_at(form, t)
    n = q.size
    free = free_mask(form, q, v)
    a, F, Ma = np.empty(n), np.empty(n), np.empty(n)
    form.acceleration(t, q, v, a)
    form.force(t, q, v, F)
    form.mass_apply(a, Ma)
    assert np.all(F[~free] == 0.0) and np.all(Ma[~free] == 0.0)
    # M a = F with a from the formulation's own direct solve of M (backward stable): a residual
    # ~ eps ||M|| ||a|| <= eps cond(M) ||F||, 1e-9 allowing cond(M) up to ~1e6
    assert np.linalg.norm(Ma - F) <= 1e-9 * np.linalg.norm(F)

    def force(qq, vv):
        out = np.empty(n)
        form.force(t, qq, vv, out)
        return out

    def diff(q, v, x, e, which):
        """Central difference of F along x in q (which = 0) or v (1)."""
        d = [np.zeros(n), np.zeros(n)]
        d[which] = e * x
        return (force(q + d[0], v + d[1]) - force(q - d[0], v - d[1])) / (2 * e)

    rng = np.random.default_rng(5)
    for h in (1e-5, 1e-3):
        m, c, k = 1.0, 0.55 * h, 0.3 * h * h
        factor = form.factorize(t, q, v, m, c, k)
        r = np.where(free, rng.standard_normal(n), 0.0)
        x = np.empty(n)
        factor.solve(t, r, x)
        assert np.all(x[~free] == 0.0)
        # F is linear in v and at most cubic in q: a unit-size difference in v is exact, and
        # Richardson's (4 D(e/2) - D(e)) / 3 removes the e^2 error of the central one in q
        e = 1e-4 / np.abs(x).max()
        Kx = -(4 * diff(q, v, x, e / 2, 0) - diff(q, v, x, e, 0)) / 3
        Cx = -diff(q, v, x, 1.0 / np.abs(x).max(), 1)
        Mx = np.empty(n)
        form.mass_apply(x, Mx)
        Sx = m * Mx + c * Cx + k * Kx
        err = np.linalg.norm(Sx - r) / np.linalg.norm(r)
        tol = 1e-5
        if name == "tlf" and not extra:
            tol += 2 * k * form.dynamics.c_rho * form.drive.rate(t) / m
        assert err < tol, (h, err, tol)


@pytest.fixture(scope="module")
def solids():
    """FFRF and GCMS on the default mesh from one set of clamped modes."""
    fam = ReducedFamily(load_scene(), COMM, count=30)
    return {m: fam.build(m) for m in ("ffrf", "gcms")}


@pytest.mark.parametrize("method", METHODS)
def test_reproduces_the_paper_transient_within_one_percent(method, solids):
    """10 ms on the default scene (TLF on [10,2,2]): at 10 times the paper's step and at the
    default step, generalised-alpha stays within 1 % of the peak deflection of the paper's
    explicit run (max over time of |U - U_ref| / max |U_ref|), reusing one factorisation (up
    to three for the nonlinear ones)."""
    if method in solids:
        form = solids[method]
    else:
        over = ["mesh.solid=[10,2,2]"] if method == "tlf" else []
        form = build(method, load_scene(overrides=over), COMM, BuildOptions(need_steady=False))
    ref = reference(form)
    assert ref.t[-1] >= 0.01 and ref.peak > 2e-3
    for dt in (10 * PAPER_INTEGRATION[method][1], implicit_step(method, 1000.0)):
        row = compare(form, ref, dt, 0.9, timing=False)
        assert row["diverged"] is None and row["steps"] == round(0.01 / dt)
        assert row["error"] < 0.01, (dt, row["error"], row["error_components"])
        assert row["factorizations"] <= (1 if method in ("ffrf", "gcms", "lebb") else 3)
        assert row["iterations"] < 2.2 * row["steps"]


@pytest.mark.parametrize("method", ["lebb", "nebb", "ancf", "tlf", "gcms"])
def test_steps_allocate_no_arrays(method):
    """Once the interpreter's own pools are warm, 30 generalised-alpha steps (Newton iterations
    and the factor's solves included) allocate at peak less than one state vector or 4 kB,
    whichever is larger (tracemalloc sees numpy buffers): the beams' state vectors are smaller
    than the few hundred bytes of numpy scalars and small index temporaries of a force
    evaluation, which do not grow with the model (ANCF 3309 B on 5, 10 and 40 elements alike);
    TLF [6,2,2] and GCMS hold one state vector of 1.2 and 0.3 kB. Warm: in a fresh interpreter
    the first ~2000 Newton iterations keep about one 64-byte block each, then the count of
    allocated blocks stops (sys.getallocatedblocks; the same whatever the step, time and model
    size: CPython's and numpy's small-object pools filling, not ours; cold, ANCF's window peaked
    at 6.8 kB). So steps run in chunks until a chunk leaves the block count where it was, which a
    leak per step never does (at most WARM_CHUNKS chunks)."""
    import sys
    import tracemalloc

    form = small(method, "load.tip_force=[10.0, 20.0, 30.0]")
    q, v = form.initial_state()
    s = GeneralizedAlpha()
    h = 1e-5
    s.start(form, 0.0, h, q, v)
    k, growth = 1, []
    while len(growth) < WARM_CHUNKS:
        blocks = sys.getallocatedblocks()
        for k in range(k, k + 100):
            s.step(form, k * h, h, q, v)
        k += 1
        growth.append(sys.getallocatedblocks() - blocks)
        if growth[-1] <= 0:
            break
    assert growth[-1] <= 0, growth
    factorizations = s.stats["factorizations"]
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    for k in range(k, k + 30):
        s.step(form, k * h, h, q, v)
    peak = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.stop()
    assert s.stats["factorizations"] == factorizations
    assert peak < max(q.nbytes, 4096), peak


#: chunks of 100 steps test_steps_allocate_no_arrays runs at most until the block count stays
WARM_CHUNKS = 40


@pytest.mark.paper
def test_tlf_on_the_default_mesh_within_one_percent():
    """TLF on the default mesh (27300 unknowns), first 3 ms: generalised-alpha at its default
    10 us step against CD at the paper's 0.5 us, one factorisation (the 10 ms figures and the
    speed-up are in docs/implicit.md)."""
    form = build("tlf", load_scene(), COMM, BuildOptions(need_steady=False))
    ref = reference(form, 3e-3)
    row = compare(form, ref, implicit_step("tlf", 1000.0), 0.9, 3e-3, timing=False)
    assert row["diverged"] is None and row["steps"] == 300
    assert row["error"] < 0.01, (row["error"], row["error_components"])
    assert row["factorizations"] == 1 and row["iterations"] < 1.5 * row["steps"]


@pytest.mark.paper
def test_bench_implicit_quick_writes_its_report(tmp_path):
    """``fxflex bench implicit --quick``: every study has a run within 1 % of the peak, and the
    tables, data and plot are written."""
    from fxflex.bench.implicit import run

    result = run(load_scene(), str(tmp_path), COMM, quick=True)
    assert all(b is not None and b["error"] <= 0.01 for b in result["best"].values())
    assert {"implicit.md", "implicit.json", "implicit.png"} <= {p.name for p in tmp_path.iterdir()}
    assert "across speeds" in (tmp_path / "implicit.md").read_text()
