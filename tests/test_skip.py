"""Work the request does not need is skipped, and skipping it changes nothing but round-off:
rotation terms at 0 rpm, extra outputs nobody reads, the system invariant matrices of the
element route."""

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.formulation import BuildOptions, build
from fxflex.scene import load_scene
from fxflex.scene.kinematics import Drive
from fxflex.time import simulate

pytestmark = pytest.mark.serial

COARSE = ["mesh.solid=[8,2,2]", "reduction.ffrf_modes=6", "reduction.gcms_modes=18",
          "mesh.beam_elements=4", "rotation.rpm=0", "load.tip_force=[10.0, 20.0, -30.0]"]


def _acceleration(form, t, seed=0):
    q0, v0 = form.initial_state()
    rng = np.random.default_rng(seed)
    q = q0 + 1e-4 * rng.standard_normal(q0.size)
    v = v0 + 1e-2 * rng.standard_normal(v0.size)
    form.constrain(t, q, v)
    out = np.empty_like(q)
    form.acceleration(t, q, v, out)
    return out


@pytest.mark.parametrize("method, extra", [
    ("ffrf", []), ("ffrf", ["rotation.profile=\"spin-up\"", "rotation.spinup_time=1e-3"]),
    ("gcms", []), ("gcms", ["damping.model=\"absolute\""]), ("tlf", []),
    ("tlf", ["damping.model=\"absolute\""]), ("lebb", []), ("nebb", []), ("ancf", []),
    ("ancf", ["damping.model=\"absolute\""])])
def test_rotation_terms_dropped_at_rest_change_nothing(method, extra, monkeypatch):
    """At 0 rpm each method drops its rotation operators; the acceleration agrees with the
    general path (rotation terms multiplied by zero) to round-off."""
    scene = load_scene(overrides=COARSE + extra)
    options = BuildOptions(need_steady=False)
    skipped = build(method, scene, MPI.COMM_SELF, options)
    monkeypatch.setattr(Drive, "at_rest", property(lambda self: False))
    general = build(method, scene, MPI.COMM_SELF, options)
    for t in (1e-4, 5e-4):                       # in and after the load ramp
        a, b = _acceleration(skipped, t), _acceleration(general, t)
        assert np.abs(b).max() > 0
        # the same arithmetic in two orders (skipped steps replayed): round-off accumulated over the
        # run
        assert np.abs(a - b).max() <= 1e-10 * np.abs(b).max(), (t, np.abs(a - b).max())


def test_extras_only_computed_when_read():
    form = build("lebb", load_scene(overrides=["rotation.rpm=1000"]), MPI.COMM_SELF)
    calls = []
    real = form.extras
    form.extras = lambda t, q, v: calls.append(t) or real(t, q, v)
    silent = simulate(form, "ab2", 1e-6, 50e-6, sample_every=1)
    assert silent.steps == 50 and calls == []
    rows = []
    loud = simulate(form, "ab2", 1e-6, 50e-6, sample_every=1,
                    on_sample=lambda t, tip, ex, q: rows.append(ex))
    assert len(calls) == len(rows) == loud.samples == 51 and len(rows[-1]) == 1
    assert np.array_equal(silent.tip, loud.tip)
    simulate(form, "ab2", 1e-6, 50e-6, on_sample=lambda *a: rows.append(a[2]), extras=False)
    assert len(calls) == 51 and rows[-1] == ()


@pytest.mark.parametrize("method", ["nebb", "ancf"])
def test_element_route_builds_no_system_matrices(method):
    scene = load_scene(overrides=["mesh.beam_elements=4"])
    element = build(method, scene, MPI.COMM_SELF, BuildOptions(force_eval="element"))
    invariant = build(method, scene, MPI.COMM_SELF, BuildOptions(force_eval="invariant"))
    assert element.engine.K1h is None                # the invariant route: on first use
    invariant.steady_state()                         # the element route: none for a steady state
    assert invariant.engine.K1h is None
    a, b = _acceleration(element, 1e-4), _acceleration(invariant, 1e-4)
    assert np.abs(a - b).max() <= 1e-9 * np.abs(b).max()
    assert element.engine.K1h is None                # the time loop never builds them
    assert invariant.engine.K1h is not None          # its time loop does


@pytest.mark.parametrize("method", ["lebb", "nebb"])
def test_frame_beams_make_the_inverse_mass_products_only_for_a_time_loop(method):
    """A steady state and its linearisation never need M^-1 and its products: not made at build
    nor by them; initial_state (before a time loop's clock) makes them, and a loop that starts
    without it (a resumed run) gets them on first use, the same matrices."""
    scene = load_scene(overrides=["mesh.beam_elements=4"])
    form = build(method, scene, MPI.COMM_SELF)
    form.steady_state()
    form.linearise()
    assert "Minv" not in vars(form) and "MiK" not in vars(form)
    form.initial_state()
    assert "Minv" in vars(form)
    other = build(method, scene, MPI.COMM_SELF)
    assert np.array_equal(other.MiK, form.MiK)                 # on first use
    a, b = np.zeros(form.dof), np.zeros(form.dof)
    q = 1e-4 * np.random.default_rng(1).standard_normal(form.dof)
    fresh = build(method, scene, MPI.COMM_SELF)
    form.acceleration(1e-4, q, q, a)
    fresh.acceleration(1e-4, q, q, b)                          # no initial_state
    assert np.array_equal(a, b)
