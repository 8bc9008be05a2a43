"""The converged reference: Richardson extrapolation, Q2 elements, the stored values."""

import math

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.analysis import reference as refmod
from fxflex.scene import load_scene
from fxflex.solid.model import SolidModel

COMM = MPI.COMM_WORLD


@pytest.mark.parametrize("levels", [(2, 4, 8), (3, 4, 6)])
def test_richardson_recovers_order_and_limit(levels):
    """f(h) = f0 + C h^p (+ a faster term), equal and unequal refinement ratios."""
    h = 1.0 / np.array(levels, float)
    f = 2.5 - 0.7 * h**1.6 + 1e-4 * h**4
    p, f0 = refmod.richardson(h, f)
    assert p == pytest.approx(1.6, abs=0.01) and f0 == pytest.approx(2.5, abs=1e-5)


def test_richardson_refuses_oscillating_convergence():
    assert refmod.richardson([1.0, 0.5, 0.25], [1.0, 1.2, 1.1]) == (None, None)
    assert refmod.richardson([1.0, 0.5, 0.25], [1.0, 1.0, 1.0]) == (None, None)


def test_extrapolate_and_estimate_from_two_families():
    """Four Q2 levels and four Q1 levels of a known limit: the reference is the Q2 value, the
    error estimate covers the gap to the Q1 extrapolation."""
    levels = [3, 4, 6, 8]
    h = 1.0 / np.array(levels, float)
    exact = np.array([1e-4, -4e-4, -3e-3])
    q2 = exact[None, :] * (1 + 0.02 * h[:, None] ** 1.5)
    q1 = exact[None, :] * (1 - 0.5 * h[:, None] ** 2 + 0.01 * h[:, None] ** 3)
    e2, e1 = refmod.extrapolate(levels, q2), refmod.extrapolate(levels, q1)
    value, error = refmod._combine(e2, e1, q2)
    # Richardson extrapolation of exact synthetic data: round-off of the fit
    assert np.allclose(value, exact, rtol=1e-9)
    assert all(err >= abs(v - x) for err, v, x in zip(error, value, e1["extrapolated_m"]))
    assert np.all(np.array(error) < 1e-3 * np.abs(exact))


@pytest.mark.parametrize("degree", [1, 2])
def test_line_load_sums_to_the_total(degree):
    """Consistent nodal forces of the centerline load: q L in total, Newton-Cotes weights."""
    scene = load_scene()
    model = SolidModel(scene, COMM, divisions=(8, 2, 2), degree=degree)
    b = model.line_load_vector()
    total = COMM.allreduce(b.getArray()[2::3].sum())
    q, L = scene.load.line_load, scene.geometry.length
    # the root node's share q h / (2 or 6) goes into the clamp
    root_share = q * L / 8 * (0.5 if degree == 1 else 1 / 6)
    # exact Newton-Cotes weights summed: round-off
    assert total == pytest.approx(q * L - root_share, rel=1e-12)
    local = {round(w / (q * L / 8), 12) for w in b.getArray()[2::3] if w != 0}
    weights = sorted(set().union(*COMM.allgather(local)))
    assert np.allclose(weights, [0.5, 1.0] if degree == 1 else [1 / 6, 1 / 3, 2 / 3])


def test_q2_converges_faster_than_q1():
    """Linear equilibrium at 1000 rpm: Q2 on (32, 4, 2) is closer to the stored reference than
    Q1 on a mesh with the same unknowns (64, 8, 4), by far."""
    from fxflex.solid.small_strain import linear_steady

    ref = refmod.stored_reference(load_scene())
    assert ref is not None, "fxflex/data/reference.json is missing"
    exact = ref["theories"]["linear"]["1000"]["reference_m"]
    s = load_scene()
    w = s.rotation.omega
    q2 = SolidModel(s, COMM, divisions=(32, 4, 2), degree=2)
    q1 = SolidModel(s, COMM, divisions=(64, 8, 4))
    assert q2.dof == q1.dof == 8640
    e2 = refmod.relative_error(linear_steady(q2, w).tip, exact)
    e1 = refmod.relative_error(linear_steady(q1, w).tip, exact)
    assert e2 < 2e-3 and e1 > 10 * e2, (e2, e1)


def test_stored_reference_is_keyed_by_what_the_equilibrium_depends_on():
    base = load_scene()
    key = refmod.reference_key(base)
    same = load_scene(overrides=["rotation.rpm=5000", "mesh.solid=[10,2,2]", "damping.c=100",
                                 "mesh.beam_elements=4"])
    assert refmod.reference_key(same) == key
    for change in ("material.E=200e9", "geometry.twist_deg=0", "damping.model=absolute"):
        assert refmod.reference_key(load_scene(overrides=[change])) != key
    ref = refmod.stored_reference(base)
    assert ref is not None and ref["key"] == key and not ref["quick"]
    assert refmod.stored_reference(load_scene(overrides=["material.E=200e9"])) is None
    assert ref["command"].startswith("fxflex bench accuracy --reference")
    for theory in refmod.THEORIES:
        for rpm in ("1000", "5000", "10000"):
            entry = ref["theories"][theory][rpm]
            assert entry["relative_error_estimate"] < 1e-3
            assert all(o is not None and 1.0 < o < 4.5 for o in entry["Q2"]["order"][::2])


@pytest.mark.paper
def test_stored_level_is_reproduced():
    """The Q2 m = 3 TLF equilibrium at 1000 rpm (26208 unknowns) as stored, to 1e-8."""
    from fxflex.solid.tlf import tlf_steady

    ref = refmod.stored_reference(load_scene())
    row = next(r for r in ref["levels"] if r["family"] == "Q2" and r["m"] == 3
               and r["theory"] == "tlf" and r["rpm"] == 1000.0)
    model = SolidModel(load_scene(), COMM, divisions=refmod.divisions(3), degree=2)
    tip = tlf_steady(model, 1000 * math.pi / 30, rtol=1e-9).tip
    assert np.allclose(tip, row["tip_m"], rtol=1e-8, atol=1e-14)


@pytest.mark.parallel
def test_q2_equilibrium_does_not_depend_on_the_ranks():
    """TLF on Q2 (16, 2, 1) at 5000 rpm: distributed and one-process tips agree."""
    from fxflex.solid.tlf import tlf_steady

    s = load_scene()
    w = 5000 * math.pi / 30
    par = tlf_steady(SolidModel(s, COMM, divisions=(16, 2, 1), degree=2), w).tip
    ser = tlf_steady(SolidModel(s, MPI.COMM_SELF, divisions=(16, 2, 1), degree=2), w).tip
    # Newton to rtol 1e-10 on both sides (quadratic: the last step leaves ~1e-12); distributed sums
    # round differently
    assert np.allclose(par, ser, rtol=1e-9, atol=1e-15)
