"""LEBB (Eq. 36-44): element matrices against the textbook, nodal exactness, spinning bar,
steady state of Eq. 59 and the drive torque."""

import numpy as np
import pytest

from fxflex.beam import lebb
from fxflex.beam.frame import FloatingFrameBeam

from .conftest import UNIFORM


def textbook_stiffness(E, G, A, Iy, Iz, J, L):
    """Euler-Bernoulli 12 x 12 element stiffness, nodes (u, v, w, th_x, th_y, th_z)."""
    K = np.zeros((12, 12))
    K[np.ix_([0, 6], [0, 6])] = E * A / L * np.array([[1, -1], [-1, 1]])
    K[np.ix_([3, 9], [3, 9])] = G * J / L * np.array([[1, -1], [-1, 1]])
    bend = lambda s: np.array([[12, 6 * s * L, -12, 6 * s * L],
                               [6 * s * L, 4 * L**2, -6 * s * L, 2 * L**2],
                               [-12, -6 * s * L, 12, -6 * s * L],
                               [6 * s * L, 2 * L**2, -6 * s * L, 4 * L**2]]) / L**3
    K[np.ix_([1, 5, 7, 11], [1, 5, 7, 11])] = E * Iz * bend(1)
    K[np.ix_([2, 4, 8, 10], [2, 4, 8, 10])] = E * Iy * bend(-1)
    return K


def textbook_mass(rho, A, Iy, Iz, L):
    """Consistent mass (translation) + rotary inertia of the section (th_Y, th_Z rows of N_c)
    + torsional inertia rho J_polar L / 6 [[2, 1], [1, 2]]: what N_c of Eq. 36 brings."""
    M = np.zeros((12, 12))
    M[np.ix_([0, 6], [0, 6])] = rho * A * L / 6 * np.array([[2, 1], [1, 2]])
    M[np.ix_([3, 9], [3, 9])] = rho * (Iy + Iz) * L / 6 * np.array([[2, 1], [1, 2]])
    trans = lambda s: rho * A * L / 420 * np.array(
        [[156, 22 * s * L, 54, -13 * s * L], [22 * s * L, 4 * L**2, 13 * s * L, -3 * L**2],
         [54, 13 * s * L, 156, -22 * s * L], [-13 * s * L, -3 * L**2, -22 * s * L, 4 * L**2]])
    rot = lambda s, I: rho * I / (30 * L) * np.array(
        [[36, 3 * s * L, -36, 3 * s * L], [3 * s * L, 4 * L**2, -3 * s * L, -L**2],
         [-36, -3 * s * L, 36, -3 * s * L], [3 * s * L, -L**2, -3 * s * L, 4 * L**2]])
    M[np.ix_([1, 5, 7, 11], [1, 5, 7, 11])] = trans(1) + rot(1, Iz)
    M[np.ix_([2, 4, 8, 10], [2, 4, 8, 10])] = trans(-1) + rot(-1, Iy)
    return M


def section(scene):
    b, h = scene.geometry.root_y, scene.geometry.root_z
    return b * h, b * h**3 / 12, h * b**3 / 12      # A, I_Y = int Z^2, I_Z = int Y^2


@pytest.mark.parametrize("torsion", ["polar", "saint-venant"])
def test_element_matrices_equal_textbook(uniform, torsion):
    scene = uniform.replace(**{"section.torsion": torsion})
    form = lebb.build(scene, None)
    E, G, rho = scene.material.E, scene.material.G, scene.material.rho
    A, Iy, Iz = section(scene)
    from fxflex.mesh.geometry import saint_venant_rectangle
    J = Iy + Iz if torsion == "polar" else float(saint_venant_rectangle(0.12, 0.06))
    L = form.line.le
    for e in (0, form.line.n_el - 1):
        K = textbook_stiffness(E, G, A, Iy, Iz, J, L)
        # element matrices by quadrature against textbook closed forms: exact up to round-off
        np.testing.assert_allclose(form.KLe[e], K, rtol=0, atol=1e-13 * np.abs(K).max())
        M = textbook_mass(rho, A, Iy, Iz, L)
        np.testing.assert_allclose(form.Me[e], M, rtol=0, atol=1e-13 * np.abs(M).max())


def solve_tolerance(form) -> float:
    """Relative accuracy of the steady state at rest, a direct solve with K: n eps cond(K)
    (1.1e6 for the 10 default elements), so nodally exact means exact to that."""
    return form.K.shape[0] * np.finfo(float).eps * np.linalg.cond(form.K)


def test_cantilever_tip_is_nodally_exact(uniform):
    """qL^4 / (8 E I) to round-off: cubic Hermite with consistent loads is nodally exact."""
    form = lebb.build(uniform, None)
    st = form.steady_state()
    A, Iy, _ = section(uniform)
    ref = uniform.load.line_load * uniform.geometry.length**4 / (8 * uniform.material.E * Iy)
    assert st.converged
    assert abs(st.tip[2] / ref - 1) < solve_tolerance(form)
    assert abs(st.tip[0]) < 1e-15 and abs(st.tip[1]) < 1e-15


def test_tip_force_cantilever(uniform):
    """A rotating-frame tip force F_Y at rest: F L^3 / (3 E I_Z), exact."""
    scene = uniform.replace(**{"load.line_load": 0.0, "load.tip_force": (0.0, 1000.0, 0.0)})
    form = lebb.build(scene, None)
    tip = form.steady_state().tip
    _, _, Iz = section(scene)
    assert tip[1] == pytest.approx(1000.0 / (3 * scene.material.E * Iz), rel=solve_tolerance(form))


def test_spinning_bar_elongation(uniform):
    """Bar from the axis, no transverse load: rho Omega^2 L^3 / (3E) (the linear theory also
    softens by the centrifugal load on the stretched position, +1.6e-4 here)."""
    scene = uniform.replace(**{"rotation.rpm": 1000.0, "load.line_load": 0.0})
    tip = lebb.build(scene, None).steady_state().tip
    ref = scene.material.rho * scene.rotation.omega**2 / (3 * scene.material.E)
    assert tip[0] == pytest.approx(ref, rel=5e-3)
    assert abs(tip[1]) < 1e-12 * ref and abs(tip[2]) < 1e-12 * ref


def test_hub_radius_adds_the_hub_term(uniform):
    """Bar at hub radius R: u(L) = rho Omega^2 (L^3/3 + R L^2 / 2) / E (linear theory)."""
    R = 0.5
    scene = uniform.replace(**{"rotation.rpm": 1000.0, "load.line_load": 0.0,
                               "geometry.hub_radius": R})
    tip = lebb.build(scene, None).steady_state().tip
    E, rho, w = scene.material.E, scene.material.rho, scene.rotation.omega
    assert tip[0] == pytest.approx(rho * w**2 * (1 / 3 + R / 2) / E, rel=5e-3)


def test_inertia_of_the_undeformed_beam(uniform):
    """I0 = int rho (X^2 + Y^2) dV = rho A L^3 / 3 + rho I_Z L for a uniform beam at R = 0."""
    form = lebb.build(uniform, None)
    A, _, Iz = section(uniform)
    rho = uniform.material.rho
    # exact quadrature of polynomials: round-off
    assert form.I0 == pytest.approx(rho * A / 3 + rho * Iz, rel=1e-12)


def test_gyroscopic_matrix_is_skew_and_softening_symmetric(default):
    form = lebb.build(default, None)
    # symmetry of assembled products: exact up to the order of summation
    np.testing.assert_allclose(form.G, -form.G.T, atol=1e-14 * np.abs(form.G).max())
    np.testing.assert_allclose(form.N, form.N.T, atol=1e-14 * np.abs(form.N).max())
    assert np.all(np.linalg.eigvalsh(form.N) > 0)     # the paper: M_rr6 positive definite


@pytest.mark.parametrize("model", ["relative", "absolute"])
def test_drive_torque_at_steady_state(default, model):
    """At constant speed in equilibrium the relative model needs no torque; the absolute model
    needs c/rho Omega (n.W + W.N W) > 0 to overcome its drag."""
    scene = default.replace(**{"damping.model": model})
    form = lebb.build(scene, None)
    W = form.steady_state().q
    (torque,) = form.extras(1.0, W, np.zeros_like(W))
    # round-off scale: the torque of the largest terms that cancel in M^-1 K_L W
    scale = np.abs(form.g) @ (np.abs(form.MiK) @ np.abs(W))
    expect = 0.0
    if model == "absolute":
        expect = form.c_rho * scene.rotation.omega * (form.n @ W + W @ form.N @ W)
        assert expect > 1e-11 * scale
    assert torque == pytest.approx(expect, abs=1e-15 * scale)


def test_relative_damping_does_not_move_the_steady_state(default):
    tips = [lebb.build(default.replace(**{"damping.c": c}), None).steady_state().tip
            for c in (100.0, 1000.0)]
    # c does not enter the relative model's equilibrium: the same solve
    np.testing.assert_allclose(tips[0], tips[1], rtol=1e-12)


def test_10000_rpm_is_unstable_1000_stable(default):
    """Eq. 59: K_L - Omega^2 M_rr6 loses definiteness; an eigenvalue with positive real part."""
    for rpm, unstable in ((1000.0, False), (10000.0, True)):
        form = lebb.build(default.replace(**{"rotation.rpm": rpm}), None)
        rate, _ = form.growth_rate()
        assert (rate > 0) == unstable
        n_neg = np.sum(np.linalg.eigvalsh(form.K - form.scene.rotation.omega**2 * form.N) < 0)
        assert (n_neg > 0) == unstable


def test_protocol(default):
    from fxflex.formulation import Formulation
    form = lebb.build(default, None)
    assert isinstance(form, Formulation) and isinstance(form, FloatingFrameBeam)
    assert form.dof == lebb.dof_count(default) == 60
    assert form.comm.size == 1
