"""[tip_mass] on the solids FFRF, GCMS, TLF (SPEC section 10, issue 16; fxflex.solid.tip_mass):
a rigid body on the nodes at the tip (mu (x) I_3), exact for every rigid motion of them; against the
beams carrying the same body on the same geometry, the frequency equations (tip mass with rotary
inertia; a disc on a shaft), FFRF against TLF at 3000 rpm and a transient.

Every comparison of two models states its own gap without the tip mass, and asks of the change the
tip mass makes that it agree to that gap: the body enters both as the same point (the beams:
frame.py point_quadratic; the solids: mu (x) I_3), so what differs with it is what differed
without it. The meshes are the 10 x 2 x 2 Q2 of tests/solid/test_q2.py. Serial and MPI safe: every
build is collective and replicates its results, so every rank asserts the same numbers."""

import math

import numpy as np
import pytest
from mpi4py import MPI
from scipy.optimize import brentq

from fxflex.analysis.modes import modes_of
from fxflex.errors import SceneError
from fxflex.formulation import BuildOptions, build
from fxflex.scene import Scene, load_scene
from fxflex.scene.load import validate_for

from ..conftest import iteration_matrix_error
from ..conftest import tip_body_root as _tip_body_root

COMM = MPI.COMM_WORLD
MESH = ["mesh.solid=[10,2,2]", "mesh.solid_degree=2", "geometry.twist_deg=0", "damping.c=0",
        "load.line_load=0"]
#: enough clamped modes for the axial stretch at 3000 rpm (8 hold no axial mode)
MODES = ["reduction.ffrf_modes=30", "reduction.gcms_modes=90"]


def _scene(mu: float, rpm: float = 0.0, *extra: str) -> Scene:
    """The default (tapered) blade on the small Q2 mesh with a tip mass of mu times the mass of a
    bar of the root section and the blade's length."""
    g, rho = Scene().geometry, Scene().material.rho
    mass = mu * rho * g.root_y * g.root_z * g.length
    return load_scene(overrides=MESH + MODES + [f"rotation.rpm={rpm}",
                                                 f"tip_mass.mass={mass!r}", *extra])


def _first(method: str, scene: Scene) -> dict[str, float]:
    """The first out-of-plane and in-plane frequencies (Hz)."""
    m = modes_of(build(method, scene, COMM if method in ("ffrf", "gcms", "tlf") else None,
                       BuildOptions()), 6)
    f = list(m.frequencies_hz)
    return {fam: float(f[m.labels.index(fam)]) for fam in ("out-of-plane", "in-plane")}


def _uniform(mass: float, inertia, rpm: float = 0.0, *extra: str) -> Scene:
    """A uniform solid (0.12 x 0.06 x 1 m, the small Q2 mesh) with a tip body."""
    return load_scene(overrides=MESH + MODES + UNIFORM + [
        f"rotation.rpm={rpm}", f"tip_mass.mass={mass!r}",
        f"tip_mass.inertia={[float(j) for j in inertia]!r}", *extra])


#: the uniform solid's section, and its mass per length
UNIFORM = ["geometry.tip_y=0.12", "geometry.tip_z=0.06"]
BAR = Scene().material.rho * 0.12 * 0.06


def test_the_body_is_rigid_for_any_rotation():
    """mu (x) I_3 on the tip nodes: for a rigid motion v_a = v_c + omega x (A r_a) with a large
    rotation A, 1/2 v^T M_tip v is the rigid body's 1/2 m |v_c|^2 + 1/2 omega^T J' omega,
    J' = A J A^T, to round-off; X0^T (mu (x) P) X0 = m X_c^T P X_c + tr(P Pi); the loads
    (mu (x) B) X0 against mu applied to B X0. Q1 and Q2, bodies flat in the tip plane."""
    from scipy.spatial.transform import Rotation

    from fxflex.scene.kinematics import P3, S3
    from fxflex.solid.model import SolidModel
    from fxflex.solid.reduction import nodal
    from fxflex.solid.tip_mass import TipBody

    rng = np.random.default_rng(7)                      # the same draws on every rank
    for degree, J in ((2, (0.027, 0.015, 0.012)), (1, (0.3, 0.1, 0.2))):
        sc = _uniform(3.0, J, 0.0, f"mesh.solid_degree={degree}")
        model = SolidModel(sc, COMM)
        body = TipBody(model)
        r = model.node_coordinates() - body.Xc
        A = Rotation.from_rotvec(rng.standard_normal(3)).as_matrix()
        vc, omega = rng.standard_normal(3), rng.standard_normal(3)
        v = (vc + np.cross(omega, r @ A.T)).reshape(-1)
        Mv = np.zeros_like(v)
        body.apply(v, Mv)
        energy = 0.5 * COMM.allreduce(float(v @ Mv))
        Pi = A @ sc.tip_mass.second_moments() @ A.T
        exact = 0.5 * 3.0 * vc @ vc + 0.5 * omega @ (np.trace(Pi) * np.eye(3) - Pi) @ omega
        assert energy == pytest.approx(exact, rel=1e-12)
        moment = 3.0 * body.Xc @ P3 @ body.Xc + np.trace(P3 @ sc.tip_mass.second_moments())
        assert body.second_moment(P3) == pytest.approx(moment, rel=1e-12)
        for B in (P3, S3):                  # the loads (mu (x) B) X0 = mu applied to B_d X0
            dense = np.zeros(v.size)
            body.apply(nodal(B, model.node_coordinates().reshape(-1)), dense)
            err = COMM.allreduce(float(np.abs(body.load(B) - dense).max()), op=MPI.MAX)
            assert err <= 1e-12 * COMM.allreduce(float(np.abs(dense).max()), op=MPI.MAX)


def test_a_flat_body_needs_no_layer_behind_and_every_solid_takes_one_along_x():
    """The solids carry the body on the tip face: one flat in the tip plane (J_X = J_Y + J_Z,
    decimals as typed) builds even on a Q1 mesh of one element layer; one with extent along X
    ([J, J, J]) too, on the face's normal (numerics.director.Director; GCMS: TipDirector),
    by all three solids."""
    sc = load_scene(overrides=["mesh.solid=[1,2,2]", "reduction.ffrf_modes=6",
                               "reduction.gcms_modes=18", "tip_mass.mass=1",
                               "tip_mass.inertia=[0.3, 0.1, 0.2]"])
    for method in ("ffrf", "gcms"):
        validate_for(method, sc)
        modes_of(build(method, sc, COMM, BuildOptions()), 3)
    sphere = sc.replace(**{"tip_mass.inertia": (0.1, 0.1, 0.1)})
    for method in ("ffrf", "gcms", "tlf"):
        validate_for(method, sphere)
    assert build("gcms", sphere, COMM, BuildOptions()).tip_director is not None


def _director_model(inertia=(0.02, 0.03, 0.025)):
    from fxflex.solid.model import SolidModel
    from fxflex.solid.tip_mass import TipBody

    model = SolidModel(_uniform(3.0, inertia), COMM)
    return model, TipBody(model)


def _largest(x: np.ndarray) -> float:
    return COMM.allreduce(float(np.abs(x).max(initial=0.0)), op=MPI.MAX)


def test_director_derivatives_against_finite_differences():
    """tip_mass.Director: J = B_n W against central differences of n(y) (h = 1e-6: error
    h^2 times third derivatives, ~1e-11 of |J|; asserted 1e-7); the steady derivative
    W^T K6 W against differences of the steady force (with and without the absolute damping's
    circulatory term); n'' = J y'' + k along a quadratic path against a second difference
    (h = 1e-4: error ~1e-8 of |n''|; asserted 1e-5); the velocity force is Pi_XX B_n^T k. At a
    random, strained configuration (3 cm node displacements on a 0.12 x 0.06 m face)."""
    model, body = _director_model()
    d = body.director
    rng = np.random.default_rng(3)                      # the same draws on every rank
    n = model.n_owned
    U, dU = 3e-2 * rng.standard_normal(n), rng.standard_normal(n)
    y1, y2 = rng.standard_normal(n), rng.standard_normal(n)

    def normal(U):
        return d.normal(d.gradients(d.x0 + U))[1]

    h = 1e-6
    fd = (normal(U + h * dU) - normal(U - h * dU)) / (2 * h)
    B, nn, c, Pn, Bn = d.normal(d.gradients(d.x0 + U))
    assert np.abs(fd - Bn @ d.gradients(dU).reshape(-1)).max() < 1e-7 * np.abs(fd).max()
    for w2, circulatory in ((1e4, 0.0), (1e4, 37.0)):
        def force(U):
            return d.spread(d.rotating(U, w2, circulatory)[1])
        fd = (force(U + h * dU) - force(U - h * dU)) / (2 * h)
        an = d.spread(d.rotating(U, w2, circulatory)[2] @ d.gradients(dU).reshape(-1))
        assert _largest(fd - an) < 1e-7 * _largest(an)
    h = 1e-4

    def path(t):
        return U + t * y1 + 0.5 * t * t * y2
    ndd = (normal(path(h)) - 2 * normal(path(0.0)) + normal(path(-h))) / h**2
    rate = d.gradients(y1)
    cdot = B @ rate.reshape(-1)
    ndot = Pn @ cdot / c
    k = (Pn @ (2 * np.cross(rate[0], rate[1])) - 2 * ndot * (nn @ cdot)) / c - nn * (ndot @ ndot)
    an = Bn @ d.gradients(y2).reshape(-1) + k
    assert np.abs(ndd - an).max() < 1e-5 * np.abs(an).max()
    assert np.allclose(d.moving(U, y1), d.pi * Bn.T @ k, rtol=0, atol=1e-12 * np.abs(k).max())


@pytest.mark.parametrize("inertia", [(0.1, 0.1, 0.1), (0.0, 0.05, 0.05), (0.02, 0.03, 0.025)])
def test_a_body_with_extent_along_x_is_rigid_for_any_rotation(inertia):
    """The flat part (TipBody, mu (x) I_3) plus the director's Pi_XX J^T J at the rotated
    configuration: for a rigid motion of the face with a large rotation A, the kinetic energy is
    the rigid body's 1/2 m |v_c|^2 + 1/2 omega^T J' omega to round-off (a sphere, a rod along X,
    a general body); the director is the rotated e_X. And the Woodbury inverse of the lumped mass
    with both parts against applying them: (D + M_tip + Pi_XX J^T J) x = r to round-off
    (capacitances of condition < 1e5)."""
    from scipy.spatial.transform import Rotation

    model, body = _director_model(inertia)
    d = body.director
    rng = np.random.default_rng(11)
    r = model.node_coordinates() - body.Xc
    A = Rotation.from_rotvec(rng.standard_normal(3)).as_matrix()
    vc, omega = rng.standard_normal(3), rng.standard_normal(3)
    q = (body.Xc + r @ A.T).reshape(-1) - d.x0
    v = (vc + np.cross(omega, r @ A.T)).reshape(-1)
    assert np.allclose(d.normal(d.gradients(d.x0 + q))[1], A[:, 0], rtol=0, atol=1e-12)
    Mv = np.zeros_like(v)
    body.apply(v, Mv)
    d.moving(q, v)
    d.mass_apply(v, Mv)
    energy = 0.5 * COMM.allreduce(float(v @ Mv))
    Pi = A @ np.diag(0.5 * np.sum(inertia) - np.asarray(inertia)) @ A.T
    exact = 0.5 * 3.0 * vc @ vc + 0.5 * omega @ (np.trace(Pi) * np.eye(3) - Pi) @ omega
    assert energy == pytest.approx(exact, rel=1e-12)
    m = model.lumped_mass()
    body.diagonal(m)

    def base(x):
        x /= m
        body.woodbury(x)

    d.prepare(base)
    d.moving(q, v)
    rhs = rng.standard_normal(m.size)
    x = rhs.copy()
    base(x)
    d.woodbury(x)
    back = m * x
    body.apply(x, back)
    d.mass_apply(x, back)
    assert _largest(back - rhs) < 1e-11 * _largest(rhs)


def test_cache_keys_carry_the_tip_mass():
    from fxflex.solid.reduction import reduced_key

    plain, heavy = _scene(0.0), _scene(1.0)
    assert reduced_key(plain, "ffrf", 8) != reduced_key(heavy, "ffrf", 8)
    assert reduced_key(plain, "ffrf", 8) == reduced_key(_scene(0.0), "ffrf", 8)


@pytest.mark.parametrize("inertia", [(0.0, 0.0, 0.0), (0.027, 0.015, 0.012)])
def test_woodbury_inverse_of_the_lumped_mass_with_the_body(inertia):
    """(D + M_tip)^-1 of :meth:`TipBody.woodbury` against M_tip applied by :meth:`TipBody.apply`:
    (D + M_tip) x = r to round-off. The capacitance C^-1 + V^T D^-1 V is 1 x 1 per direction
    for a point mass and 3 x 3 with the inertia; its condition number (printed) times the unit
    round-off bounds the error, far inside 1e-12 (measured: condition 2.5e4, error 2e-14)."""
    from fxflex.solid.model import SolidModel
    from fxflex.solid.tip_mass import TipBody

    model = SolidModel(_scene(1.0, 0.0, f"tip_mass.inertia={list(inertia)!r}"), COMM)
    body = TipBody(model)
    d = model.lumped_mass()
    rng = np.random.default_rng(COMM.rank)
    r = rng.standard_normal(d.size)
    x = r / d
    body.diagonal(d)
    body.woodbury(x)
    back = d * x
    body.apply(x, back)
    err = COMM.allreduce(float(np.abs(back - r).max(initial=0.0)), op=MPI.MAX)
    scale = COMM.allreduce(float(np.abs(r).max(initial=0.0)), op=MPI.MAX)
    cond = max(np.linalg.cond(c) for c in np.linalg.inv(body._cap_inv))
    print(f"\ncapacitance condition {cond:.3g}, error {err / scale:.2e}")
    assert err < 1e-12 * scale and cond < 1e-3 / np.finfo(float).eps
    # the body's translation is that of the tip probe for a rigid translation of the face
    t = np.tile([1.0, -2.0, 0.5], d.size // 3)
    assert np.allclose(body.translation(t), [1.0, -2.0, 0.5], rtol=0, atol=1e-12)


@pytest.mark.parametrize("method", ["ffrf", "gcms", "tlf"])
@pytest.mark.parametrize("mu", [0.2, 1.0, 5.0])
def test_frequency_drop_with_a_tip_mass_follows_lebb(method, mu):
    """At rest: f(mu) / f(0) of the first flap and lead-lag modes against LEBB's on the same
    tapered geometry, within the solid-vs-beam gap of f(0) itself (measured: flap 0.43 %,
    in-plane 0.24 %; the ratios agree to 0.12 % and 0.10 % at mu = 1)."""
    solid0, solid = _first(method, _scene(0.0)), _first(method, _scene(mu))
    beam0, beam = _first("lebb", _scene(0.0)), _first("lebb", _scene(mu))
    for fam in solid:
        gap = abs(solid0[fam] / beam0[fam] - 1.0)
        drop_s, drop_b = solid[fam] / solid0[fam], beam[fam] / beam0[fam]
        print(f"\n{method} mu {mu} {fam}: gap {gap:.3%}, drop {drop_s:.5f} vs {drop_b:.5f}")
        assert drop_s < 1.0 - 0.05 * mu / (1 + mu)          # the mass does lower it
        assert abs(drop_s / drop_b - 1.0) < gap


def _tip_mass_root(mu: float) -> float:
    """The lowest root bL of 1 + cos cosh + mu bL (cos sinh - sin cosh) = 0 (mu = M_t / rho A L)."""
    f = lambda x: (1 + math.cos(x) * math.cosh(x)
                   + mu * x * (math.cos(x) * math.sinh(x) - math.sin(x) * math.cosh(x)))
    return brentq(f, 0.05, 1.8751041)


@pytest.mark.parametrize("mu", [0.1, 1.0, 5.0])
def test_mass_ratio_scaling_of_a_uniform_solid_against_the_frequency_equation(mu):
    """A uniform solid (0.12 x 0.06 x 1 m): the first flap frequency's ratio f(mu) / f(0) against
    (bL(mu) / bL(0))^2 of the Euler-Bernoulli frequency equation, within the solid's own gap to
    Euler-Bernoulli at mu = 0 (shear, rotary inertia, Poisson, discretisation; measured 0.2 %)."""
    uniform = ["geometry.tip_y=0.12", "geometry.tip_z=0.06"]
    mat = Scene().material
    exact0 = 1.8751040687**2 * math.sqrt(mat.E * 0.06**2 / 12.0 / mat.rho) / (2 * math.pi)
    f0 = _first("ffrf", _scene(0.0, 0.0, *uniform))["out-of-plane"]
    f = _first("ffrf", _scene(mu, 0.0, *uniform))["out-of-plane"]
    gap = abs(f0 / exact0 - 1.0)
    ratio = (_tip_mass_root(mu) / 1.8751040687) ** 2
    print(f"\nmu {mu}: gap {gap:.3%}, ratio {f / f0:.5f} vs {ratio:.5f}")
    assert abs((f / f0) / ratio - 1.0) < gap


def _euler_bernoulli_hz(depth: float) -> float:
    mat = Scene().material
    return 1.8751040687**2 * math.sqrt(mat.E * depth**2 / 12.0 / mat.rho) / (2 * math.pi)


@pytest.mark.parametrize("method", ["ffrf", "gcms", "tlf"])
@pytest.mark.parametrize("mu,j", [(1.0, 0.05), (0.2, 0.1)])
def test_rotary_inertia_of_a_tip_body_against_the_frequency_equation(method, mu, j):
    """The uniform solid with a thin disc [2 J, J, J] (J = j rho A L^3 about Y for the flap mode,
    about Z for the lead-lag one): the share of the rotary inertia in the first bending
    frequencies, f(mu, j) / f(mu, 0), against (bL(mu, j) / bL(mu, 0))^2 of the frequency
    equation, within the solid's own gap to Euler-Bernoulli at mu = 0 for that direction (shear,
    rotary inertia, Poisson, discretisation; measured: the shares agree to 2.5e-4 / 2.2e-3 out of
    plane and 5.2e-4 / 1.4e-3 in plane, against a 4 % / 20 % drop; gaps 0.55 % / 0.45 %)."""
    J = j * BAR
    bare = _first(method, _uniform(0.0, (0, 0, 0)))
    point = _first(method, _uniform(mu * BAR, (0, 0, 0)))
    body = _first(method, _uniform(mu * BAR, (2 * J, J, J)))
    share = (_tip_body_root(mu, j) / _tip_body_root(mu, 0.0)) ** 2
    for fam, depth in (("out-of-plane", 0.06), ("in-plane", 0.12)):
        gap = abs(bare[fam] / _euler_bernoulli_hz(depth) - 1.0)
        ours = body[fam] / point[fam]
        print(f"\n{method} mu {mu} j {j} {fam}: {ours:.6f} vs {share:.6f}, gap {gap:.2e}")
        assert ours < 0.99                              # the inertia does lower it
        assert abs(ours / share - 1.0) < gap


def _torsion(method: str, scene: Scene) -> float:
    m = modes_of(build(method, scene, COMM if method in ("ffrf", "gcms", "tlf") else None,
                       BuildOptions()), 8)
    return float(m.frequencies_hz[m.labels.index("torsion")])


@pytest.mark.parametrize("method", ["ffrf", "tlf"])
@pytest.mark.parametrize("ratio", [0.3, 3.0])
def test_torsion_with_a_tip_disc_against_the_shaft_equation(method, ratio):
    """A thin disc [2 J, J, J] (J_X = ratio rho I_p L) on the uniform solid at rest: f(J) / f(0)
    against beta L / (pi / 2) of beta L tan(beta L) = rho I_p L / J_X (a uniform shaft: the
    ratio does not depend on its torsion stiffness), within the solid's own gap to the uniform
    Saint-Venant shaft (LEBB with section.torsion "saint-venant": the root's warping restraint
    makes the solid stiffer near the root; measured gap 2.4 %, ratio -0.38 % / -0.92 %)."""
    Ip = 0.12 * 0.06 * (0.12**2 + 0.06**2) / 12.0
    Jx = ratio * Scene().material.rho * Ip * 1.0
    bl = brentq(lambda x: x * math.tan(x) - 1.0 / ratio, 1e-9, math.pi / 2 - 1e-12, xtol=1e-15)
    f0 = _torsion(method, _uniform(0.0, (0, 0, 0)))
    f = _torsion(method, _uniform(0.0, (Jx, Jx / 2, Jx / 2)))
    shaft = _torsion("lebb", _uniform(0.0, (0, 0, 0), 0.0, *BEAM_SV))
    gap = abs(f0 / shaft - 1.0)
    print(f"\n{method} ratio {ratio}: {f / f0:.6f} vs {bl / (math.pi / 2):.6f}, gap {gap:.2e}")
    assert f / f0 < 0.8
    assert abs((f / f0) / (bl / (math.pi / 2)) - 1.0) < gap


#: the beams beside the uniform solid: 20 elements, Saint-Venant torsion
BEAM_SV = ("mesh.beam_elements=20", 'section.torsion="saint-venant"')


@pytest.mark.parametrize("mu,j", [(1.0, 0.05), (0.2, 0.1)])
def test_a_rod_along_x_has_the_rotary_inertia_of_the_frequency_equation(mu, j):
    """TLF with a rod along X, inertia [0, J, J] (Pi_XX = J: tip_mass.Director's normal n
    carries all of it), on the uniform solid at rest: the share of the rotary inertia in the
    first flap and lead-lag frequencies against the frequency equation, within the solid's own
    gap to Euler-Bernoulli, as the disc [2 J, J, J] of the test above; and the rod's first
    bending frequencies against the disc's, which has the same J_Y and J_Z, within the same gap
    (measured: equal to 1e-6; the share as the disc's)."""
    J = j * BAR
    bare = _first("tlf", _uniform(0.0, (0, 0, 0)))
    point = _first("tlf", _uniform(mu * BAR, (0, 0, 0)))
    rod = _first("tlf", _uniform(mu * BAR, (0.0, J, J)))
    disc = _first("tlf", _uniform(mu * BAR, (2 * J, J, J)))
    share = (_tip_body_root(mu, j) / _tip_body_root(mu, 0.0)) ** 2
    for fam, depth in (("out-of-plane", 0.06), ("in-plane", 0.12)):
        gap = abs(bare[fam] / _euler_bernoulli_hz(depth) - 1.0)
        ours = rod[fam] / point[fam]
        print(f"\nrod mu {mu} j {j} {fam}: {ours:.6f} vs {share:.6f}, disc {disc[fam] / point[fam]:.6f}"
              f", gap {gap:.2e}")
        assert ours < 0.99
        assert abs(ours / share - 1.0) < gap
        assert abs(rod[fam] / disc[fam] - 1.0) < 1e-5    # the solid's own gap cancels here


def test_rotating_rod_along_x_stiffens_the_flap_as_nebb():
    """At 3000 rpm a rod along X (inertia [0, P, P], Pi = diag(P, 0, 0)) tilted by a flap
    rotation theta meets a centrifugal restoring moment Omega^2 P theta (the propeller moment of
    J_Z - J_X = P): it raises the rotating flap frequency against the one at rest, where it only
    adds J_Y. Its share, (f_rod / f_bare at 3000 rpm) / (the same at rest), TLF (director, about
    the prestressed equilibrium) against NEBB (second-order point rotation): the stiffening
    itself, share - 1 (4 %), within the pair's flap frequency gap at rest without the body
    (0.62 %; measured 0.33 %; J_X + J_Y - J_Z = 0: the rod couples flap to torsion in
    neither). And the rod moves the steady tip (twist 45 deg, the line load tilts
    it) as NEBB's does, within twice the pair's own gap in the transverse tip deflection
    without the body, or in flap frequency, the larger: the rod adds no axial stretch (its pull
    is along its own axis; TLF: to 1e-8 of the stretch)."""
    P = 0.02 * BAR

    def share(m: str, *extra: str) -> float:
        f = {(J, rpm): _first(m, _uniform(0.0, J, rpm, *extra))["out-of-plane"]
             for J in ((0, 0, 0), (0, P, P)) for rpm in (0.0, 3000.0)}
        return (f[(0, P, P), 3000.0] / f[(0, 0, 0), 3000.0]) / (f[(0, P, P), 0.0]
                                                                 / f[(0, 0, 0), 0.0])

    solid, ref = share("tlf"), share("nebb", *BEAM_SV)
    bare = _uniform(0.0, (0, 0, 0))
    bare_beam = _uniform(0.0, (0, 0, 0), 0.0, *BEAM_SV)
    flap_gap = abs(_first("tlf", bare)["out-of-plane"]
                   / _first("nebb", bare_beam)["out-of-plane"] - 1.0)
    print(f"\nrod: share {solid:.5f} vs {ref:.5f}, gap {flap_gap:.2e}")
    assert solid > 1.03                                # the propeller moment stiffens, 4 %
    assert abs((solid - 1.0) / (ref - 1.0) - 1.0) < flap_gap   # the stiffening itself
    tips = {}
    for m in ("tlf", "nebb"):
        for J in ((0, 0, 0), (0, P, P)):
            sc = _uniform(BAR, J, 3000.0, "geometry.twist_deg=45", "load.line_load=100",
                          *(BEAM_SV if m == "nebb" else ()))
            tips[m, J] = build(m, sc, COMM if m == "tlf" else None,
                               BuildOptions()).steady_state().tip
    moved = {m: tips[m, (0, P, P)] - tips[m, (0, 0, 0)] for m in ("tlf", "nebb")}
    print(f"rod moves the tip: tlf {moved['tlf']}, nebb {moved['nebb']}")
    assert abs(moved["tlf"][0]) < 1e-8 * abs(tips["tlf", (0, 0, 0)][0])
    base = {m: tips[m, (0, 0, 0)][1:] for m in ("tlf", "nebb")}
    static_gap = np.linalg.norm(base["tlf"] - base["nebb"]) / np.linalg.norm(base["nebb"])
    print(f"static gap {static_gap:.2e}")
    assert np.linalg.norm(moved["tlf"][1:] - moved["nebb"][1:]) < (
        2.0 * max(static_gap, flap_gap) * np.linalg.norm(moved["nebb"][1:]))


@pytest.mark.parametrize("method,beam", [("ffrf", "lebb"), ("gcms", "lebb"), ("tlf", "nebb")])
def test_rotating_tip_body_softens_the_flap_as_the_beams(method, beam):
    """At 3000 rpm a body with second moments Pi = diag(0, 0, P) (inertia [P, P, 0]) softens the
    flap rotation by -Omega^2 P and couples it to torsion gyroscopically (2 Omega P): for this
    body the beams' linearised point terms are the rigid body's exact ones. Its share of the
    rotating flap frequency, (f_body / f_bare at 3000 rpm) / (the same at rest), of the solid
    against the beam with Saint-Venant torsion (the coupling depends on the torsion frequency),
    linear FFRF/GCMS against LEBB, TLF against NEBB (both stiffen in flap), within the pair's own
    gap at rest without the body (flap or torsion, the larger; measured 2.4 %): measured 0.2 %
    (FFRF, GCMS) and 0.16 % (TLF) against a share of 0.79 (0.85 with LEBB's polar torsion, whose
    frequency is 30 % above the solid's)."""
    P = 0.02 * BAR

    def share(m: str, *extra: str) -> float:
        f = {(J, rpm): _first(m, _uniform(0.0, J, rpm, *extra))["out-of-plane"]
             for J in ((0, 0, 0), (P, P, 0)) for rpm in (0.0, 3000.0)}
        return (f[(P, P, 0), 3000.0] / f[(0, 0, 0), 3000.0]) / (f[(P, P, 0), 0.0]
                                                                 / f[(0, 0, 0), 0.0])

    solid, ref = share(method), share(beam, *BEAM_SV)
    bare = _uniform(0.0, (0, 0, 0))
    bare_beam = _uniform(0.0, (0, 0, 0), 0.0, *BEAM_SV)
    gap = max(abs(_first(method, bare)["out-of-plane"] / _first(beam, bare_beam)["out-of-plane"]
                  - 1.0), abs(_torsion(method, bare) / _torsion(beam, bare_beam) - 1.0))
    print(f"\n{method} vs {beam}: share {solid:.5f} vs {ref:.5f}, gap {gap:.2e}")
    assert solid < 0.9                                  # the body's terms matter
    assert abs(solid / ref - 1.0) < gap


def test_steady_tip_with_a_tip_mass_ffrf_gcms_against_tlf_at_3000_rpm():
    """The tip stretch at 3000 rpm, with a tip mass pulling m Omega^2 (R + L): FFRF and GCMS
    (linear) against TLF (St.Venant-Kirchhoff) within the small-deflection difference, which
    for a stretched bar is about 3/2 of the axial strain (u' = N / EA - 3/2 (N / EA)^2 + ...):
    bounded here by twice the strain N / (E A) at the tip section, m Omega^2 (R + L) /
    (E A_tip) (measured: 0.98 % of the tip stretch, strain 0.83 %); without the tip mass all
    three agree to 0.2 %. The tip mass's share of the stretch agrees with LEBB's within LEBB's
    own gap to FFRF without it (measured 0.62 %, the share within 0.42 %)."""
    sc0, sc = _scene(0.0, 3000.0), _scene(1.0, 3000.0)
    g, E = sc.geometry, sc.material.E
    strain = sc.tip_mass.mass * sc.rotation.omega**2 * (g.hub_radius + g.length) / (
        E * g.tip_y * g.tip_z)
    tips = {m: (build(m, sc0, COMM, BuildOptions()).steady_state().tip[0],
                build(m, sc, COMM, BuildOptions()).steady_state().tip[0])
            for m in ("ffrf", "gcms", "tlf")}
    beam = tuple(build("lebb", s, None, BuildOptions()).steady_state().tip[0] for s in (sc0, sc))
    tlf0, tlf = tips["tlf"]
    for method in ("ffrf", "gcms"):
        lin0, lin = tips[method]
        print(f"\n{method}: {lin0:.5e} / {lin:.5e}, tlf {tlf0:.5e} / {tlf:.5e}, "
              f"strain {strain:.3%}")
        assert abs(lin / tlf - 1.0) < 2.0 * strain
        assert lin > 4.0 * lin0                   # the tip mass's pull dominates
    ffrf0, ffrf = tips["ffrf"]
    gap = abs(beam[0] / ffrf0 - 1.0)
    assert abs((beam[1] - beam[0]) / (ffrf - ffrf0) - 1.0) < gap


def test_rotating_flap_with_a_tip_mass_stiffens_as_nebb():
    """TLF about its rotating equilibrium at 600 rpm: the tip mass's centrifugal pull stiffens the
    first flap mode (the prestress of the steady state, the linearisation's geometric stiffness);
    its ratio to the frequency at rest against NEBB's, within the solid-vs-beam gap at rest
    (measured: 1.16170 vs 1.16211, gap 0.31 %)."""
    rest = {m: _first(m, _scene(1.0))["out-of-plane"] for m in ("tlf", "nebb")}
    turning = {m: _first(m, _scene(1.0, 600.0))["out-of-plane"] for m in ("tlf", "nebb")}
    gap = abs(rest["tlf"] / rest["nebb"] - 1.0)
    stiff = {m: turning[m] / rest[m] for m in rest}
    print(f"\ngap {gap:.3%}, stiffening {stiff}")
    assert stiff["tlf"] > 1.1
    assert abs(stiff["tlf"] / stiff["nebb"] - 1.0) < gap


def _tip_z(method: str, scene: Scene, integrator: str, t_end: float, mass: str | None = None):
    from fxflex.time import simulate

    form = build(method, scene, COMM, BuildOptions(mass=mass))
    dt = 0.9 * 2.0 / form.omega_max() if integrator == "cd" else 1e-4
    dt = t_end / round(t_end / dt)
    rows = []
    simulate(form, integrator, dt, t_end, sample_every=max(1, round(2.5e-4 / dt)),
             on_sample=lambda t, tip, extras, q: rows.append((t, tip[2])))
    return np.array(rows)


@pytest.mark.parametrize("inertia", [(0.0, 0.0, 0.0), (2.0, 1.0, 1.0), (0.0, 1.0, 1.0)])
def test_transient_with_a_tip_mass_tlf_against_ffrf(inertia):
    """At rest, a sudden tip force (the 300 us ramp): the tip's out-of-plane motion of TLF
    (generalized-alpha with both masses; central differences with the lumped mass, the body kept
    rigid by Sherman-Morrison-Woodbury) against FFRF's (generalized-alpha), with a point mass and
    with a disc of rotary inertia J_Y = 1 kg m^2 besides. Their first flap frequencies agree to
    1e-5 (modes), so over the window the phase gap is below 1e-4, and the integrators' phase
    errors ((w dt)^2 / 12 at the same or a smaller step) are of the same size: within 1e-3 of
    the peak (measured: 2e-5 over 30 ms, half the first period; without the tip mass the
    motion differs by its whole size; the disc lowers the flap frequency by 2.4 %). A rod along
    X, [0, 1, 1] (TLF's director, its mass configuration-dependent, a Woodbury update in the
    central differences), against FFRF with the disc of the same J_Y, [2, 1, 1] (flap only: J_X
    does not enter): the same bound (measured 2e-5)."""
    sc = _scene(1.0, 0.0, "load.tip_force=[0, 0, 100]", f"tip_mass.inertia={list(inertia)!r}")
    flat = (inertia[1] + inertia[2], inertia[1], inertia[2])
    sc_ref = _scene(1.0, 0.0, "load.tip_force=[0, 0, 100]", f"tip_mass.inertia={list(flat)!r}")
    ref = _tip_z("ffrf", sc_ref, "generalized-alpha", 0.03)
    peak = np.abs(ref[:, 1]).max()
    flap = _first("ffrf", sc_ref)["out-of-plane"]
    # the peak at half the first period (2.5e-4 s samples)
    assert ref[np.argmax(ref[:, 1]), 0] == pytest.approx(0.5 / flap, abs=5e-4)
    runs = [("generalized-alpha", 0.03, "consistent"), ("generalized-alpha", 0.03, "lumped"),
            ("cd", 0.004, "lumped")]
    for integrator, t_end, mass in runs:
        z = _tip_z("tlf", sc, integrator, t_end, mass)
        there = ref[ref[:, 0] <= t_end + 1e-12]
        gap = np.abs(np.interp(there[:, 0], z[:, 0], z[:, 1]) - there[:, 1]).max() / peak
        print(f"\ntlf {integrator} {mass} {inertia}: {gap:.2e} of the peak, "
              f"flap {flap:.4f} Hz, peak at {ref[np.argmax(ref[:, 1]), 0]:.5f} s")
        assert gap < 1e-3


def test_the_iteration_matrix_keeps_the_rods_mass_current():
    """Generalized-alpha's hub-frame factor of TLF serves many steps while the tip face turns;
    with a rod along X [0, 1, 1] the director's mass and d(force)/dq' change with it, and
    HubTangent.solve_hub swaps them in by Woodbury. Fresh (factorised at the state itself): S is
    Newton's Jacobian to 1e-4 (measured 3e-5; left out, the q-derivatives of the director's
    mass and force, k Omega^2 ~ 1e-7 of it, and the finite differences' error). Made 0.5 ms
    earlier: the factor's own age (the prestress and geometry of K_t; 0.83 % without a tip
    inertia, 1.8 % with the disc [2, 1, 1]) dominates, and the rod adds at most a tenth of it
    (measured 0.85 %). Without the update: 3.2e-4 fresh (d(force)/dq' left out) and 26 times
    |dx| 0.5 ms old (the factor's director mass, large on the face, turned with it)."""
    def error(inertia, t1):
        sc = _scene(1.0, 3000.0, "load.tip_force=[0, 100, 100]",
                    f"tip_mass.inertia={list(inertia)!r}")
        return iteration_matrix_error(build("tlf", sc, COMM, BuildOptions(mass="consistent")),
                                      t1)

    fresh = error((0.0, 1.0, 1.0), 0.002)
    stale, bare = (error(J, 0.0015) for J in ((0.0, 1.0, 1.0), (0, 0, 0)))
    print(f"\nrod: fresh {fresh:.2e}, 0.5 ms old {stale:.2e} (no inertia {bare:.2e})")
    assert fresh < 1e-4
    assert stale < 1.1 * bare


@pytest.mark.parametrize("inertia", [(0.0, 0.05, 0.05), (0.02, 0.03, 0.025)])
def test_ffrf_invariants_carry_the_linearised_director(inertia):
    """FFRF's invariants with a tip body of extent along X against the sums they stand for:
    the solid and the flat part of the body (mass M_flat, isotropic) plus the director
    linearised at the reference, n = e_X + J u (J = dn/dy of numerics.director.Director at X0):
    the modal mass I = Phi^T M_flat Phi + Pi_XX (J Phi)^T (J Phi) (the clamped modes see the
    director), G = Phi^T M_flat S_d Phi + Pi_XX (J Phi)^T S (J Phi) and N likewise with P
    (reduction.director_corrections: J does not commute with S_d, P_d), the Euler load g gains
    Pi_XX (J Phi)^T S e_X over the solid's and flat body's own, J0 gains Pi_XX. To 1e-10 of the
    largest entry (round-off; eigen tolerance 1e-12)."""
    from fxflex.scene.kinematics import P3, S3
    from fxflex.solid.reduction import inner, mat_apply, nodal
    from fxflex.solid.tip_mass import TipBody

    form = build("ffrf", _uniform(3.0, inertia, 0.0), COMM, BuildOptions())
    model, data, inv = form.model, form.data, form.inv
    d = data.director
    Phi = form.modes.vectors[:, : form.dof]
    body = TipBody(model)
    M_flat = model.matrix(model.compile(model.mass_form()), diagonal=0.0)
    body.add_to(M_flat)
    Bn = d.normal(d.gradients(d.x0))[4]
    part = Phi.reshape(-1, 3, Phi.shape[1])[d.nodes]
    JPhi = Bn @ COMM.allreduce(np.einsum("ak,aim->kim", d.G, part)).reshape(6, -1)

    def close(a, b):
        assert np.abs(a - b).max() <= 1e-10 * max(np.abs(b).max(), 1.0)

    close(inner(COMM, Phi, mat_apply(M_flat, Phi)) + d.pi * JPhi.T @ JPhi, np.eye(form.dof))
    for B, got in ((S3, inv.G), (P3, inv.N)):
        want = inner(COMM, Phi, mat_apply(M_flat, nodal(B, Phi))) + d.pi * JPhi.T @ B @ JPhi
        close(got, 0.5 * (want + (want.T if B is P3 else -want.T)))
    n = model.node_coordinates().shape[0] * 3
    f_S = model.vector(model.euler_form()).getArray(readonly=True)[:n] + body.load(S3)
    close(inv.g, inner(COMM, Phi, f_S) + d.pi * JPhi.T @ S3 @ np.array([1.0, 0.0, 0.0]))
    point = build("ffrf", _uniform(3.0, (0.0, 0.0, 0.0), 0.0), COMM, BuildOptions())
    pi_xx, pi_yy = (0.5 * sum(inertia) - j for j in inertia[:2])
    assert d.pi == pytest.approx(pi_xx, rel=1e-12)
    # J0 = int rho X0^T P X0 + m (R + L)^2 + tr(P Pi): the body's Pi_YY (flat) and Pi_XX
    assert inv.J0 - point.inv.J0 == pytest.approx(pi_xx + pi_yy, rel=1e-10)


def test_ffrf_rod_along_x_as_lebb():
    """FFRF's director is linear (n = e_X + J u), as LEBB's point terms for Pi_XX: at rest the rod
    along X [0, P, P] has the disc's [2 P, P, P] bending frequencies (to 1e-5); at 3000 rpm its
    share of the rotating flap frequency (against rest) is 1 within 1e-4 in both (measured
    0.99997: the Coriolis share), and of the lead-lag frequency LEBB's within the pair's own
    lead-lag gap at rest (measured 0.97295 vs 0.97259 against 0.17 %). The linear theory keeps only the linear share of
    the rod's centrifugal terms: it softens lead-lag by -Omega^2 P (the linearised n leaves the
    unit sphere) and leaves flap alone, where TLF and NEBB, exact in the rotation, have no
    lead-lag effect and the propeller stiffening (shares 1.002 and 1.040)."""
    P = 0.02 * BAR
    f = {}
    for m, extra in (("ffrf", ()), ("lebb", BEAM_SV)):
        for J in ((0, 0, 0), (0, P, P), (2 * P, P, P)):
            for rpm in (0.0, 3000.0):
                f[m, J, rpm] = _first(m, _uniform(0.0, J, rpm, *extra))
    for fam in ("out-of-plane", "in-plane"):
        assert f["ffrf", (0, P, P), 0.0][fam] == pytest.approx(f["ffrf", (2 * P, P, P), 0.0][fam],
                                                               rel=1e-5)
        gap = abs(f["ffrf", (0, 0, 0), 0.0][fam] / f["lebb", (0, 0, 0), 0.0][fam] - 1.0)
        share = {m: (f[m, (0, P, P), 3000.0][fam] / f[m, (0, 0, 0), 3000.0][fam])
                 / (f[m, (0, P, P), 0.0][fam] / f[m, (0, 0, 0), 0.0][fam]) for m in ("ffrf", "lebb")}
        print(f"\n{fam}: shares ffrf {share['ffrf']:.5f} lebb {share['lebb']:.5f}, gap {gap:.2e}")
        if fam == "out-of-plane":                      # the linear theories: no flap effect
            assert abs(share["ffrf"] - 1.0) < 1e-4 and abs(share["lebb"] - 1.0) < 1e-4
        else:                                          # lead-lag: -Omega^2 P softening, 2.7 %
            assert share["ffrf"] < 0.98 and abs(share["ffrf"] / share["lebb"] - 1.0) < gap


@pytest.mark.parametrize("model", ["relative", "absolute"])
def test_tlf_steady_state_is_a_rest_point_of_the_time_loop_with_a_rod(model):
    """TLF (consistent mass) with a rod along X [0, 0.01, 0.01], twisted 30 deg, line load,
    3000 rpm, damped (c = 1000): at its steady state turned to phi(t), moving rigidly with the
    hub, the time loop's acceleration seen from the hub, A^T a + Omega^2 P (X0 + U), vanishes
    on the free nodes to 3e-9 of the centripetal scale Omega^2 |X0 + U| (the steady Newton's
    tolerance, 1e-10 of the undeformed residual, leaves ~3e-10: measured 2.6e-10 / 3.6e-10).
    With the absolute damping model the time loop damps the director's own rate relative to the
    rigidly turning e_X, as the steady state does (Director.absolute_damping): without it,
    2.9e-8."""
    from fxflex.scene.kinematics import P3, S3, rotation_z

    sc = load_scene(overrides=["mesh.solid=[8,2,2]", "load.line_load=-20000", "rotation.rpm=3000",
                               "tip_mass.mass=1.0", "tip_mass.inertia=[0, 0.01, 0.01]",
                               f'damping.model="{model}"', "damping.c=1000",
                               "geometry.twist_deg=30", "load.ramp_time=0"])
    form = build("tlf", sc, COMM, BuildOptions(mass="consistent"))
    U = np.asarray(form.steady_state().q)
    X0 = form.model.node_coordinates().reshape(-1, 3)
    omega, t = sc.rotation.omega, 0.3e-3
    A = rotation_z(form.drive.angle(t))
    x_hub = X0 + U.reshape(-1, 3)
    x = x_hub @ A.T
    q = (x - X0).reshape(-1)
    v = (omega * x @ S3.T).reshape(-1)
    a = np.zeros_like(q)
    form.acceleration(t, q, v, a)
    hub = (a.reshape(-1, 3) @ A + omega**2 * x_hub @ P3.T).reshape(-1)
    free = np.ones(q.size, bool)
    free[form.dynamics.root] = False
    scale = omega**2 * _largest(x_hub)
    print(f"\n{model}: rest-point acceleration {_largest(hub[free]) / scale:.2e} of the scale")
    assert _largest(hub[free]) < 3e-9 * scale


# -- GCMS: the linearised director in absolute coordinates (gcms.TipDirector) ----------------------

def _gcms_rod(rpm: float, *extra: str, inertia=(0.0, 0.05, 0.05)):
    return build("gcms", _uniform(BAR, inertia, rpm, *extra), COMM, BuildOptions())


@pytest.mark.parametrize("model", ["relative", "absolute"])
def test_gcms_director_rows_are_dalembert_of_the_turning_normal(model):
    """GCMS with a rod along X during a spin-up (phi, phi', phi'' all nonzero), damped, at a
    random state xi, xi' scaled so that every term of the director is of the same size (the
    damping too: c / rho = 382 1/s against phi' = 203 rad/s; dropping the director's damping
    errs by 9e-5): its
    share of the xi rows, M(phi) xi'' - F = (mass_apply - force) minus the same without it,
    against the virtual work of the director's inertia and damping written from its definition
    alone, n(phi, xi) = A(phi) (e_X + b R(phi)^T xi):

        Pi_XX (dn/dxi)^T (n'' + (c/rho) rate),  rate = n' - phi' S n   (relative)
                                                      n' - phi' S A e_X (absolute),

    with n', n'' by central differences in time along xi(t) = xi + s xi' + s^2 / 2 xi'' and
    phi(t) of the drive, dn/dphi by central differences in phi; and the phi row (drive torque)
    against Pi_XX n'' . dn/dphi + (c/rho) Pi_XX rate . A S e_X (the damping's lever at the
    reference, as FFRF's). Both to 1e-6 of the largest term: the differences, Richardson-
    extrapolated from h = 1 and 0.5 us, are left with O(h^4) (1e-5 of |n''| at h = 1 us before
    extrapolation, falling as h^2: the state's fast modes) and round-off eps |n| / h^2 ~ 1e-12 of
    |n''| (8e8 here)."""
    from fxflex.scene.kinematics import S3, rotation_z
    from fxflex.solid.reduction import ReducedFormulation

    form = _gcms_rod(3000.0, "rotation.profile=spin-up", "rotation.spinup_time=0.004",
                     "damping.c=3e6", f'damping.model="{model}"')
    td = form.tip_director
    rng = np.random.default_rng(11)
    t = 0.0023
    phi, w, a = form.drive.state(t)
    zb = np.linalg.lstsq(td.b, np.ones(3), rcond=None)[0]       # b z ~ 1: every term counts
    q = rng.standard_normal(form.dof) * np.abs(zb).max() + zb
    v = w * (rng.standard_normal(form.dof) * np.abs(zb).max())
    acc = np.empty(form.dof)
    form.acceleration(t, q, v, acc)
    e_x = np.array([1.0, 0.0, 0.0])

    def n_of(phi_: float, xi: np.ndarray) -> np.ndarray:
        return rotation_z(phi_) @ (e_x + td.b @ (form.rotation(phi_).T @ xi))

    def n_at(s: float) -> np.ndarray:
        return n_of(form.drive.angle(t + s), q + s * v + 0.5 * s * s * acc)

    def differences(h: float) -> tuple[np.ndarray, np.ndarray]:
        n_p, n_m = n_at(h), n_at(-h)
        return (n_p - n_m) / (2 * h), (n_p - 2 * n0 + n_m) / (h * h)

    n0 = n_at(0.0)
    (d1, d2), (h1, h2) = differences(1e-6), differences(0.5e-6)    # Richardson: O(h^4)
    n1, n2 = (4.0 * h1 - d1) / 3.0, (4.0 * h2 - d2) / 3.0
    dn_dphi = (n_of(phi + 1e-6, q) - n_of(phi - 1e-6, q)) / 2e-6
    dn_dxi = rotation_z(phi) @ td.b @ form.rotation(phi).T
    rate = n1 - w * (S3 @ (n0 if model == "relative" else rotation_z(phi) @ e_x))
    cr = form.c_rho
    want = td.pi * dn_dxi.T @ (n2 + cr * rate)
    f_iso, f, Ma = np.empty(form.dof), np.empty(form.dof), np.empty(form.dof)
    ReducedFormulation.acceleration(form, t, q, v, f_iso)
    form.force(t, q, v, f)
    form.mass_apply(acc, Ma)
    got = (Ma - acc) - (f - f_iso)
    print(f"\n{model}: xi rows {np.abs(got - want).max() / np.abs(want).max():.2e}")
    assert np.abs(got - want).max() <= 1e-6 * np.abs(want).max()
    tau = td.torque((phi, w, a), form.rotation(phi), q, v, acc)
    tau_want = td.pi * (n2 @ dn_dphi + cr * rate @ (rotation_z(phi) @ S3 @ e_x))
    scale = td.pi * np.abs(n2).max() * np.abs(dn_dphi).max()
    print(f"torque {tau:.6e} vs {tau_want:.6e}")
    assert abs(tau - tau_want) <= 1e-6 * scale


@pytest.mark.parametrize("model", ["relative", "absolute"])
def test_gcms_steady_state_with_a_rod_is_a_rest_point_of_its_time_loop(model):
    """GCMS with a rod along X at 3000 rpm, damped, tip force: its rotating-frame equilibrium
    zeta (RotatingSystem with the director's M, G, N, n) turned to xi = R(phi) zeta, moving with
    the hub (xi' = Omega J xi), has the time loop's acceleration Omega^2 J^2 xi, and M(phi) of
    mass_apply times it is force()'s F: to the same 1e-6 of |xi''| as without the rod (the
    Gram cut leaves R orthogonal to its round-off: measured 2.8e-7, without the rod 1.4e-7)."""
    def residual(inertia):
        form = _gcms_rod(3000.0, "load.tip_force=[0, 100, 100]", "damping.c=2000",
                         f'damping.model="{model}"', "load.ramp_time=0", inertia=inertia)
        st = form.steady_state()
        t, w, J = 0.37e-3, form.omega_s, form.gm.J
        xi = form.rotation(form.drive.angle(t)) @ st.q
        v = w * J @ xi
        a, f, Ma = (np.empty_like(xi) for _ in range(3))
        form.acceleration(t, xi, v, a)
        want = w * w * J @ (J @ xi)
        form.force(t, xi, v, f)
        form.mass_apply(want, Ma)
        assert np.allclose(form.tip(t, xi), st.tip, rtol=1e-12, atol=0)
        scale = np.abs(want).max()
        return max(np.abs(a - want).max(), np.abs(f - Ma).max() / np.abs(Ma).max() * scale
                   ) / scale

    rod, bare = residual((0.0, 0.05, 0.05)), residual((0.0, 0.0, 0.0))
    print(f"\n{model}: rest-point residual {rod:.2e} (without the rod {bare:.2e})")
    assert rod < 1e-6 and bare < 1e-6


def test_gcms_iteration_matrix_is_the_exact_jacobian_with_a_rod():
    """GCMS's equations are linear in (xi, xi', xi''), so generalized-alpha's iteration matrix
    S = m M + c C_t + k K_t (factorised at phi = 0 and turned by R(phi), the director's share
    from TipDirector.iteration_matrix) solves the Newton residual's change exactly: S^-1 (r(x) -
    r(0)) = x with r(x) = M x - F(q + k x, v + c x), during a damped spin-up with a rod, both
    damping models, at k = 1e-9, c = 3e-5 (a 60 us step: every share of S counts), to ten
    times R's own departure from orthogonality (the Gram cut's round-off, which the rotated
    factor inherits; measured 5.5e-9 against 1.7e-8; leaving out the -phi' C_d J of K_t: 5e-5).
    x is large (1e8) so that r(x) - r(0) does not lose it to F's own size."""
    for model in ("relative", "absolute"):
        form = _gcms_rod(3000.0, "rotation.profile=spin-up", "rotation.spinup_time=0.004",
                         "damping.c=3000", f'damping.model="{model}"')
        rng = np.random.default_rng(3)
        t, m, c, k = 0.0027, 1.0, 3e-5, 1e-9
        q, v = (rng.standard_normal(form.dof) for _ in range(2))
        x = 1e8 * rng.standard_normal(form.dof)
        R = form.rotation(form.drive.angle(t))
        skew = np.abs(R.T @ R - np.eye(form.dof)).max()

        def r(y):
            f, My = np.empty(form.dof), np.empty(form.dof)
            form.force(t, q + k * y, v + c * y, f)
            form.mass_apply(y, My)
            return My - f

        lu = form.factorize(t, q, v, m, c, k)
        dx = np.empty(form.dof)
        lu.solve(t, r(x) - r(np.zeros(form.dof)), dx)
        err = np.abs(dx - x).max() / np.abs(x).max()
        print(f"\n{model}: |S^-1 dr - x| / |x| = {err:.2e}, |R^T R - I| {skew:.1e}")
        assert err < 10.0 * skew + 1e-12


def test_gcms_rod_along_x_as_ffrf():
    """GCMS is a Galerkin FFRF on span(Psi~), which holds FFRF's clamped modes: with the rod
    along X [0, P, P] its first flap and lead-lag frequencies equal FFRF's at rest (both exact
    on the lowest clamped modes) to GCMS's dense eigensolve's round-off, 10 eps |K_r| /
    lambda_1 (3.9e-9; measured 2e-11), and at 3000 rpm within twice the pair's own gap with
    the body's flat part alone (Pi_XX = 0: no director; the larger span; measured 6.7e-8 vs
    7.2e-8), as is the steady tip with a tip force (FFRF's and GCMS's spans differ the same with
    and without the director; measured 1.74e-4 vs 1.70e-4). A sphere [P, P, P] (flat part: the
    disc [P, P/2, P/2]) likewise."""
    from scipy.linalg import eigvalsh

    P = 0.02 * BAR
    for J, flat in (((0.0, P, P), (0, 0, 0)), ((P, P, P), (P, P / 2, P / 2))):
        lin = build("gcms", _uniform(0.0, J, 0.0), COMM, BuildOptions()).linearise()
        roundoff = 10.0 * np.finfo(float).eps * np.linalg.norm(lin.K, 2) / eigvalsh(
            lin.K, lin.M, subset_by_index=[0, 0])[0]
        for rpm in (0.0, 3000.0):
            f = {(m, body): _first(m, _uniform(0.0, body, rpm))
                 for m in ("ffrf", "gcms") for body in (J, flat)}
            for fam in ("out-of-plane", "in-plane"):
                gap, bare = (abs(f["gcms", body][fam] / f["ffrf", body][fam] - 1.0)
                             for body in (J, flat))
                print(f"\n{J} {rpm:.0f} rpm {fam}: {gap:.2e} (without the director {bare:.2e}, "
                      f"round-off {roundoff:.1e})")
                assert gap < (roundoff if rpm == 0.0 else 2.0 * bare + roundoff)
        tips = {(m, body): build(m, _uniform(0.0, body, 3000.0, "load.tip_force=[0, 100, 100]"),
                                 COMM, BuildOptions()).steady_state().tip
                for m in ("ffrf", "gcms") for body in (J, flat)}
        gap, bare = (np.abs(tips["gcms", b] - tips["ffrf", b]).max() / np.abs(tips["ffrf", b]).max()
                     for b in (J, flat))
        print(f"steady tip gap {gap:.2e} (without the director {bare:.2e})")
        assert gap < 2.0 * bare + 1e-12


def test_gcms_spin_up_with_a_rod_follows_ffrf():
    """A damped 3 ms spin-up to 3000 rpm with a tip force and the rod along X [0, P, P]:
    GCMS's tip history and drive torque (generalized-alpha, 2 us) against FFRF's, within twice
    their gap with the disc [2 P, P, P] (no director; the same J_Y, J_Z: the pair's own span
    difference with a rotary inertia; measured 7.4e-5 against 5.4e-5 of the peak); and the
    undamped, unloaded spin-up's drive work beyond the rigid part equals the deformation energy
    as without the body (tests/solid/test_ffrf.py; to 1e-4)."""
    from fxflex.time import simulate

    from .test_ffrf import work_and_energy

    P = 0.02 * BAR
    over = ("rotation.profile=spin-up", "rotation.spinup_time=0.003",
            "load.tip_force=[0, 100, 100]", "damping.c=2000")
    runs = {}
    for body in ((0.0, P, P), (2 * P, P, P)):
        for m in ("ffrf", "gcms"):
            form = build(m, _uniform(BAR, body, 3000.0, *over), COMM, BuildOptions())
            res = simulate(form, "generalized-alpha", 2e-6, 0.004, sample_every=10,
                           keep_history=True)
            runs[m, body] = np.array(res.history)
    gap = {body: (np.abs(runs["gcms", body][:, 1:] - runs["ffrf", body][:, 1:]).max(axis=0)
                  / np.abs(runs["ffrf", body][:, 1:]).max(axis=0)).max()
           for body in ((0.0, P, P), (2 * P, P, P))}
    print(f"\nGCMS vs FFRF: rod {gap[0.0, P, P]:.2e}, disc {gap[2 * P, P, P]:.2e}")
    assert gap[0.0, P, P] < 2.0 * gap[2 * P, P, P]
    form = build("gcms", _uniform(0.0, (0.0, P, P), 3000.0, "rotation.profile=spin-up",
                                  "rotation.spinup_time=0.003", "damping.c=0"),
                 COMM, BuildOptions())
    work, e_ = work_and_energy(form, form.gm.J0 + form.gm.pi)
    print(f"work vs energy {np.abs(work - e_).max() / np.abs(e_).max():.2e}")
    assert np.abs(work - e_).max() <= 1e-4 * np.abs(e_).max()


@pytest.mark.parametrize("model", ["relative", "absolute"])
def test_gcms_with_a_rod_is_the_galerkin_ffrf_on_its_span(model):
    """GCMS is FFRF on span(Psi~) in the coordinates xi = R zeta (gcms module docstring): built
    here the other way, FFRF's invariants (fxflex.solid.ffrf.ffrf_invariants, the director by
    reduction.director_corrections) on GCMS's own basis Psi~ with the whole mass M (modal mass
    M_z = Psi~^T M Psi~, not I), its rows solved at random zeta, zeta' during a spin-up with a
    tip force and turned to xi: GCMS's acceleration and kinetic energy are the same to ten times
    R's departure from orthogonality (the Gram cut's round-off; measured 2e-8 and 4e-16 against
    1.7e-8) with a large damping (c / rho = 382 1/s, so that its terms count), and M_z = I + M_d.
    The drive torque too, undamped (measured 1.4e-9): damped, the phi rows at fixed xi (GCMS) and
    at fixed zeta (FFRF) differ by the damping's virtual work on d zeta / d phi = -J zeta,
    (c/rho) (J zeta) . (M_z zeta') for the relative model (D_rf2 neglected in both)."""
    from fxflex.solid.ffrf import ffrf_invariants
    from fxflex.solid.reduction import inner, mat_apply

    damped = _gcms_rod(3000.0, "rotation.profile=spin-up", "rotation.spinup_time=0.004",
                       "damping.c=3e6", f'damping.model="{model}"',
                       "load.tip_force=[30, 100, 100]", "load.ramp_time=0.003")
    B, _ = damped.nodal_basis()
    inv = ffrf_invariants(damped.model, damped.data, B)
    Mz = inner(COMM, B, mat_apply(damped.data.M, B))
    Mz = 0.5 * (Mz + Mz.T)
    ab = 1.0 if model == "absolute" else 0.0
    rng = np.random.default_rng(5)
    for g in (damped, damped.at(damping=0.0)):
        cr = g.c_rho
        for t in (0.0021, 0.0047):
            phi, w, a = g.drive.state(t)
            r, R, J = g.ramp(t), g.rotation(phi), g.gm.J
            skew = np.abs(R.T @ R - np.eye(g.dof)).max()
            z = 1e-4 * rng.standard_normal(g.dof)
            zd = 1e-4 * w * rng.standard_normal(g.dof)
            rhs = (r * inv.fe - a * inv.g + w * w * inv.n - (2 * w * inv.G + cr * Mz) @ zd
                   - (inv.Lambda + a * inv.G - w * w * inv.N + ab * cr * w * inv.G) @ z)
            zdd = np.linalg.solve(Mz, rhs)
            xi, xid = R @ z, R @ (zd + w * J @ z)
            want = R @ (zdd + 2 * w * J @ zd + a * J @ z + w * w * J @ J @ z)
            got = np.empty(g.dof)
            g.acceleration(t, xi, xid, got)
            Nz, Gz = inv.N @ z, inv.G @ z
            T = (0.5 * w * w * (inv.J0 + 2 * inv.n @ z + z @ Nz) + w * (inv.g + Gz) @ zd
                 + 0.5 * zd @ Mz @ zd)
            errs = [np.abs(got - want).max() / np.abs(want).max(),
                    abs(g.kinetic_energy(t, xi, xid) - T) / abs(T)]
            if cr == 0.0:
                tau = (a * (inv.J0 + 2 * inv.n @ z + z @ Nz) + 2 * w * (inv.n + Nz) @ zd
                       + (inv.g + Gz) @ zdd - r * (inv.s0 + inv.b @ z))
                errs.append(abs(g.drive_torque(t, xi, xid) - tau) / abs(tau))
            print(f"\n{model} c/rho {cr:.0f} t {t}: acceleration, energy[, torque] {errs}, "
                  f"|R^T R - I| {skew:.1e}")
            assert max(errs) < 10.0 * skew + 1e-12
    assert np.abs(Mz - np.eye(damped.dof) - damped.tip_director.M).max() < 10.0 * skew + 1e-12
