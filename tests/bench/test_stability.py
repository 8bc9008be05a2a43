"""bench stability's measurements on LEBB (cheap): the critical steps found by bisection on the
formulation agree with the one-mode roots, and a long run's energy decays as the damping says."""

import math

import pytest
from mpi4py import MPI

from fxflex.bench.stability import critical_step_study, long_run
from fxflex.formulation import build
from fxflex.scene import Scene


@pytest.fixture(scope="module")
def lebb():
    return build("lebb", Scene(), MPI.COMM_SELF)


def test_critical_steps_match_the_one_mode_roots(lebb):
    cd = critical_step_study(lebb, "cd")
    assert cd["omega_power"] == pytest.approx(cd["omega_max"], rel=1e-6)
    assert cd["estimate_root"] == pytest.approx(2 / cd["omega_max"], rel=1e-6)
    assert cd["measured_lo"] <= cd["estimate_root"] * 1.0005
    assert cd["measured_hi"] >= cd["estimate_root"] * 0.9995
    ab2 = critical_step_study(lebb, "ab2")
    assert ab2["ratio_to_root"] == pytest.approx(1.0, abs=5e-3)
    # the law's step is 2 % too long at h w ~ 0.18
    assert ab2["estimate_law"] / ab2["estimate_root"] == pytest.approx(1.023, abs=0.003)


@pytest.mark.parametrize("integrator", ["cd", "ab2"])
def test_long_run_energy_decays_and_ab2_grows_its_top_mode(lebb, integrator):
    r = long_run(lebb, integrator, 0.4e-6, 20000)
    # damped: the energy never exceeds its start, up to the round-off of evaluating it (~ n eps)
    assert r["stopped_at_s"] is None and r["H_max_over_ref"] < 1 + 1e-9
    assert r["H_end_over_ref"] == pytest.approx(r["H_decay_expected"], abs=1e-4)
    if integrator == "ab2":
        assert r["top_growth_measured"] == pytest.approx(r["top_growth_root"], rel=0.01)
        assert r["top_growth_law"] < r["top_growth_root"]
    else:
        assert abs(r["top_growth_measured"]) < 1.0 and math.isfinite(r["top_growth_root"])


def test_generalized_alpha_push_decays_on_a_nonlinear_model():
    """NEBB at 20 / w_max: the push along the highest mode decays. Both runs solve Newton to
    GA_TRIAL_TOL; at the default tolerance their iteration errors differ by more than the push
    and it seemed to grow 148x."""
    nebb = build("nebb", Scene(), MPI.COMM_SELF)
    ga = critical_step_study(nebb, "generalized-alpha")
    # generalised-alpha is unconditionally stable: the spectral radius is at most 1 up to round-off
    # of a 3 x 3 eig
    assert ga["max_radius"] <= 1.0 + 1e-12
    assert ga["trial_step"] * ga["omega_max"] == pytest.approx(20.0, rel=1e-3)
    assert ga["trial_growth"] < 0.1
