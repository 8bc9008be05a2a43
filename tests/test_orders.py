"""Fitted convergence orders on cheap versions of issue 13's cases (item 3; the model is
scikit-fem's tests/test_convergence.py): the error of a tip deflection against the element size
h = 1 / n, its least-squares slope (:func:`fxflex.analysis.convergence.fitted_order`) asserted in
an interval that theory gives and the measurements below confirm, so that a regression in an
element shows as a wrong slope.

Errors are self-convergence, so no stored number is needed: the difference to a much finer level
of the same discretisation (beams), or to the next level of a mesh-doubling sequence (solids:
for e_n = C h^p the differences e_n - e_2n = C (1 - 2^-p) h^p have the same slope). A slope
measured against a reference level n_ref is biased upwards, over levels n_1..n_k, by about
log2((1 - (n_1/n_ref)^p) / (1 - (n_k/n_ref)^p)) / log2(n_k/n_1): with n_ref = 4 n_k (the beams)
0.04 for p = 2 and 0.003 for p = 4; the intervals allow for it.

The beams are small dense models replicated on every rank: their tests are the same arithmetic
on each rank and run serially only. The solid test is distributed and runs in both suites.
"""

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.analysis.convergence import default_blade, fitted_order, slender_spinup, thin_twisted
from fxflex.formulation import BuildOptions, build
from fxflex.scene import Scene
from fxflex.solid.model import SolidModel
from fxflex.solid.small_strain import linear_steady
from fxflex.time import simulate

SELF = MPI.COMM_SELF
AXIS = {"X": 0, "Y": 1, "Z": 2}

#: the issue's uniform slender cantilever (L = 1 m, 0.04 x 0.01 m, nu = 0.28) at rest under the
#: line load; the scene of tests/beam/test_locking_free.py
SLENDER = {"geometry.length": 1.0, "geometry.root_y": 0.04, "geometry.root_z": 0.01,
           "geometry.tip_y": 0.04, "geometry.tip_z": 0.01, "geometry.twist_deg": 0.0,
           "rotation.rpm": 0.0, "material.nu": 0.28, "load.line_load": -1.0}


def steady_tips(method: str, scenes) -> np.ndarray:
    """(levels, 3) steady tip deflections of ``method`` on each scene."""
    return np.array([build(method, s, SELF).steady_state().tip for s in scenes])


def self_errors(values: np.ndarray) -> np.ndarray:
    """Each level's difference to the last (the much finer reference level), relative to it."""
    return values[:-1] / values[-1] - 1.0


# -- LEBB: Hermite cubic bending, linear axial -----------------------------------------------------
@pytest.mark.serial
@pytest.mark.parametrize("direction", ["Y", "Z"])
def test_lebb_tip_converges_at_fourth_order_on_the_twisted_cantilever(direction):
    """Thin twisted cantilever (case iii), tip deflection along the unit tip force, 4 / 8 / 16
    elements against 64. Theory: cubic Hermite elements give nodal deflections of order
    2 (p - 1) = 4 (the energy error h^(p-1), squared); they are not exact here, unlike on a
    uniform beam, because the 90 deg twist turns the principal axes along X (bending stiffness
    varying in X). Measured: Y 3.90, Z 3.92 (consecutive 3.84 / 3.96), 16 elements within 2e-5.
    A quadratic slip (a wrong shape function, a Gauss rule too short for the twisted section)
    would give 2."""
    levels = [4, 8, 16, 64]
    tips = steady_tips("lebb", [thin_twisted(direction, {"beam_elements": n}) for n in levels])
    err = self_errors(tips[:, AXIS[direction]])
    order = fitted_order(levels[:-1], err)
    print(f"\nLEBB thin twisted {direction}: order {order:.3f}, errors {err}")
    assert 3.6 < order < 4.3
    assert abs(err[-1]) < 1e-4


@pytest.mark.serial
def test_lebb_axial_tip_converges_at_second_order_on_the_default_blade():
    """The default (tapered, twisted) blade at 1000 rpm, the axial tip displacement (centrifugal
    stretch), 4 / 8 / 16 elements against 64. Theory: the linear axial element is nodally exact
    only for a constant EA; the taper makes EA vary, so the nodal error is of order 2. Measured
    2.03 (1.99 against 256 elements); the bending components converge at order 4 too but are
    within 1e-8 at 16 elements, too near the solve's round-off to fit."""
    levels = [4, 8, 16, 64]
    tips = steady_tips("lebb", [default_blade(1000.0, {"beam_elements": n}) for n in levels])
    err = self_errors(tips[:, 0])
    order = fitted_order(levels[:-1], err)
    print(f"\nLEBB default blade axial: order {order:.3f}, errors {err}")
    assert 1.8 < order < 2.3


# -- NEBB: membrane locking of the paper's element ---------------------------------------------
def spinup_tip_y(variant: str, n: int, t_end: float = 5.0, dt: float = 5e-3) -> float:
    """In-plane tip deflection W_Y (m) at t_end of the slender spin-up (case ii),
    generalized-alpha at dt."""
    scene = slender_spinup({"beam_elements": n, "beam_variant": variant})
    form = build("nebb", scene, SELF, BuildOptions(need_steady=False))
    q, v = form.initial_state()
    simulate(form, "generalized-alpha", dt, t_end, sample_every=10**9, state=(q, v), extras=False)
    return float(form.tip(t_end, q)[1])


@pytest.mark.serial
def test_nebb_locking_free_converges_at_second_order_where_the_paper_locks():
    """The issue's slender spin-up, shortened to 5 s at a 5 ms step (the step is the same on
    every level, so the differences are the spatial error), in-plane tip deflection on 4 / 8 / 16
    elements against 64. Theory: with the element-mean membrane strain the element is free of
    locking and converges at the order 2 of its linear axial field; the paper's element (linear
    axial, cubic transverse) cannot match W'^2 / 2 with its axial strain, so it is far too stiff
    with a slope well below 2 until the elements are short. Measured: locking-free 2.05
    (consecutive 2.03 / 2.06), 8 elements 0.04 % off; paper 1.13 (0.87 / 1.39), 8 elements 21 %
    off (docs/beams.md: 16.5 % at 10 elements, order 1.1-1.3)."""
    levels = [4, 8, 16, 64]
    order, err = {}, {}
    for variant in ("paper", "locking-free"):
        err[variant] = self_errors(np.array([spinup_tip_y(variant, n) for n in levels]))
        order[variant] = fitted_order(levels[:-1], err[variant])
    print(f"\nNEBB spin-up orders {order}, errors {err}")
    assert 1.8 < order["locking-free"] < 2.3
    assert 0.6 < order["paper"] < order["locking-free"] - 0.6
    assert abs(err["locking-free"][1]) < 2e-3 and abs(err["paper"][1]) > 0.1


# -- ANCF: Poisson locking of the paper's continuum -----------------------------------------------
@pytest.mark.serial
def test_ancf_locking_free_converges_at_fourth_order_where_the_paper_locks():
    """The uniform slender cantilever at rest under the line load, tip deflection on 2 / 4 / 8
    elements against 32 (finer levels reach the solve's round-off: the tips on 16 / 32 / 64 /
    128 elements change by 2.0e-9, 2.5e-9, 2.1e-8). Theory: the locking-free variant takes the
    bending curvature from the cubic Hermite centerline and ties the transverse shears to their
    nodal values
    (docs/beams.md), so what remains is a cubic-centerline Timoshenko element: order 4 at the tip
    (the cubic's error on a quartic deflection), converging to Timoshenko's deflection, EB +
    0.0085 % here. The paper's St.Venant-Kirchhoff moduli need a lateral contraction its linearly
    interpolated section gradients cannot follow, a stiffening that fades slowly (order about
    1.3). Measured: locking-free 4.06 on 2 / 4 / 8 against 32 (errors 1.2e-5 / 9.0e-7 / 4.4e-8),
    on an untwisted beam (with twist the linearly interpolated section gradients shrink the
    section mid-element, an order-2 error: docs/beams.md); paper 1.29 (1.24 / 1.35), 8 elements
    3.1 % off. The bounds: above 3 (a constant curvature per element, as before the change,
    gives 2), and the paper variant's error at 4 elements more than 1e3 times the locking-free
    one (measured 8e4)."""
    order, err = {}, {}
    for variant, levels in (("paper", [4, 8, 16, 64]), ("locking-free", [2, 4, 8, 32])):
        scenes = [Scene().replace(**SLENDER, **{"mesh.beam_elements": n,
                                                "mesh.beam_variant": variant}) for n in levels]
        err[variant] = self_errors(steady_tips("ancf", scenes)[:, 2])
        order[variant] = fitted_order(levels[:-1], err[variant])
    print(f"\nANCF slender cantilever orders {order}, errors {err}")
    assert order["locking-free"] > 3.0
    assert 0.9 < order["paper"] < 1.8
    assert abs(err["paper"][0]) > 1e3 * abs(err["locking-free"][1])      # 4 elements each


# -- solids: Q2 against the locking Q1 ------------------------------------------------------------
@pytest.mark.parametrize("direction", ["Y", "Z"])
def test_solid_q2_converges_faster_than_the_locking_q1_on_the_twisted_cantilever(direction):
    """Thin twisted cantilever (case iii), linear static tip deflection along the unit tip force,
    meshes (n, 2, 2), n = 12 / 24 / 48 / 96 (the element length refined, the section fixed:
    along X the thin section makes Q1 lock), the slope of the differences between consecutive
    levels fitted on n = 12 / 24 / 48. Theory: the smooth part of Q2's error is of order 3-4,
    but the clamp's edges (the Poisson effect, docs/accuracy.md: order 1.6 on the default blade)
    and their boundary layer under the fixed 2 x 2 section cut it in the preasymptotic range;
    Q1 is shear-locked while the elements are long against the 0.32 m thickness and its slope
    only reaches its asymptotic 2 past n = 200. Measured (consecutive slopes): Q2 Z 1.95 / 1.67
    (2.56 from n = 6), Q2 Y 2.77 / 2.52; Q1 Z 0.04 / 1.11 / 1.71, then 1.92 / 1.98 at n = 192 /
    384; Q1 Y 0.20 / 1.15 / 1.72; fitted: Q2 Z 1.81, Y 2.65, Q1 Z 0.58, Y 0.68. Q2 changes by
    0.34 % (Z) and 0.26 % (Y) from n = 12 to 24, Q1 by 14 % and 11 % from 48 to 96 (Z: 4.21e-3 at
    n = 48 against about 5.42e-3, 22 % stiff). About 2-3 s per direction, serial."""
    k = AXIS[direction]
    levels = [12, 24, 48, 96]
    order, change = {}, {}
    for degree in (1, 2):
        tips = []
        for n in levels:
            scene = thin_twisted(direction, {"solid": (n, 2, 2), "solid_degree": degree})
            model = SolidModel(scene, MPI.COMM_WORLD, divisions=(n, 2, 2), degree=degree)
            tips.append(linear_steady(model).tip[k])
        tips = np.array(tips)
        diff = np.diff(tips) / tips[-1]
        order[degree] = fitted_order(levels[:-1], diff)
        change[degree] = diff
    print(f"\nsolid thin twisted {direction}: orders Q1 {order[1]:.3f}, Q2 {order[2]:.3f}, "
          f"relative changes Q1 {change[1]}, Q2 {change[2]}")
    assert 1.5 < order[2] < 3.2
    assert 0.2 < order[1] < 1.3
    assert order[2] > order[1] + 0.8
    assert abs(change[2][0]) < 5e-3 and abs(change[1][2]) > 0.1
