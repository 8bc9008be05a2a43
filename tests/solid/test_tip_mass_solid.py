"""[tip_mass] on the solids FFRF, GCMS, TLF (SPEC section 10, issue 16; fxflex.solid.tip_mass):
a point mass moving with the tip face's rigid-fit translation, against the beams carrying the same
mass on the same geometry, the frequency equation, FFRF against TLF at 3000 rpm and a transient.

Every comparison of two models states its own gap without the tip mass, and asks of the change the
tip mass makes that it agree to that gap: the body enters both as the same point (the beams:
frame.py point_quadratic; the solids: m (w w^T) (x) I_3), so what differs with it is what differed
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


def test_solids_take_a_tip_mass_but_not_its_rotary_inertia_yet():
    mass = Scene().replace(**{"tip_mass.mass": 1.0})
    spin = Scene().replace(**{"tip_mass.mass": 1.0, "tip_mass.inertia": (0.2, 0.1, 0.1)})
    for method in ("ffrf", "gcms", "tlf"):
        validate_for(method, mass)
        with pytest.raises(SceneError) as err:
            validate_for(method, spin)
        text = str(err.value)
        assert text.startswith("tip_mass.inertia") and "allowed: inertia [0, 0, 0]" in text
        assert "\n" not in text
    validate_for("lebb", spin)


def test_cache_keys_carry_the_tip_mass():
    from fxflex.solid.reduction import reduced_key

    plain, heavy = _scene(0.0), _scene(1.0)
    assert reduced_key(plain, "ffrf", 8) != reduced_key(heavy, "ffrf", 8)
    assert reduced_key(plain, "ffrf", 8) == reduced_key(_scene(0.0), "ffrf", 8)


def test_woodbury_inverse_of_the_lumped_mass_with_the_body():
    """(D + M_tip)^-1 of :meth:`TipBody.woodbury` against M_tip applied by :meth:`TipBody.apply`:
    (D + M_tip) x = r to round-off (a 3 x 3 diagonal capacitance: no conditioning to speak of)."""
    from fxflex.solid.model import SolidModel
    from fxflex.solid.tip_mass import TipBody

    model = SolidModel(_scene(1.0), COMM)
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
    assert err < 1e-12 * COMM.allreduce(float(np.abs(r).max(initial=0.0)), op=MPI.MAX)
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


def test_transient_with_a_tip_mass_tlf_against_ffrf():
    """At rest, a sudden tip force (the 300 us ramp): the tip's out-of-plane motion of TLF
    (generalized-alpha with both masses; central differences with the lumped mass, the body kept
    a point by Sherman-Morrison-Woodbury) against FFRF's (generalized-alpha). Their first flap
    frequencies agree to 1e-5 (modes), so over the window the phase gap is below 1e-4, and the
    integrators' phase errors ((w dt)^2 / 12 at the same or a smaller step) are of the same size:
    within 1e-3 of the peak (measured: 2e-5 over 30 ms, half the first period; without the tip
    mass the motion differs by its whole size)."""
    sc = _scene(1.0, 0.0, "load.tip_force=[0, 0, 100]")
    ref = _tip_z("ffrf", sc, "generalized-alpha", 0.03)
    peak = np.abs(ref[:, 1]).max()
    assert ref[np.argmax(ref[:, 1]), 0] == pytest.approx(0.026, abs=1e-3)   # half of 1 / 19.19 Hz
    runs = [("generalized-alpha", 0.03, "consistent"), ("generalized-alpha", 0.03, "lumped"),
            ("cd", 0.004, "lumped")]
    for integrator, t_end, mass in runs:
        z = _tip_z("tlf", sc, integrator, t_end, mass)
        there = ref[ref[:, 0] <= t_end + 1e-12]
        gap = np.abs(np.interp(there[:, 0], z[:, 0], z[:, 1]) - there[:, 1]).max() / peak
        print(f"\ntlf {integrator} {mass}: {gap:.2e} of the peak")
        assert gap < 1e-3
