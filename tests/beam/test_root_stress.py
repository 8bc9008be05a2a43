"""Root-section axial stress of the beam methods against closed forms (uniform beam).

The section forces are the elastic force on the root coordinates minus the line load's share
there: the support reaction in equilibrium, so M c / I at the root of a cantilever at rest is
exact to round-off (10 elements). The spinning bar misses the centrifugal load of half the first
element, (l_e / L)^2 / 3 = 0.33 % of N.
"""

import math

import numpy as np
import pytest

from fxflex.analysis.compare import steady_time
from fxflex.formulation import build

Q, B, H, L = -800.0, 0.12, 0.06, 1.0


@pytest.mark.parametrize("method", ["lebb", "nebb", "ancf"])
def test_cantilever_root_stress_is_mc_over_i(uniform, method):
    scene = uniform.replace(**{"load.line_load": Q})
    form = build(method, scene, None)
    st = form.steady_state()
    sigma = form.root_stress(steady_time(scene), st.q)
    ref = abs(Q) * L**2 / 2 * (H / 2) / (B * H**3 / 12)
    top = form.line.shape.corners(0.0)[:, 1] > 0
    assert np.allclose(sigma[top], ref, rtol=1e-6)
    assert np.allclose(sigma[~top], -ref, rtol=1e-6)


@pytest.mark.parametrize("method", ["lebb", "ancf"])
def test_spinning_bar_root_stress_is_n_over_a(uniform, method):
    scene = uniform.replace(**{"load.line_load": 0.0, "rotation.rpm": 1000.0})
    form = build(method, scene, None)
    sigma = form.root_stress(steady_time(scene), form.steady_state().q)
    w = 1000.0 * math.pi / 30
    ref = scene.material.rho * w**2 * L**2 / 2
    le = L / scene.mesh.beam_elements
    assert np.allclose(sigma, ref, rtol=(le / L) ** 2 / 3 + 1e-3)


def test_root_stress_of_a_transient_state_matches_the_frame(default):
    """ANCF in the inertial frame: the stress of a rotated state is that of the state itself."""
    form = build("ancf", default, None)
    st = form.steady_state()
    t = steady_time(default)
    A = form.drive.A(t + 1e-4)
    q = (st.q.reshape(-1, 3) @ A.T).reshape(-1)
    # the same equilibrium evaluated at two times: the load ramp is over, so only round-off differs
    assert np.allclose(form.root_stress(t + 1e-4, q), form.root_stress(t, st.q), rtol=1e-9)
