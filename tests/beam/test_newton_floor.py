"""Newton stops at the round-off floor of its residual (fxflex.numerics.dense.newton): fine beam
meshes have stiffness entries ~ 1/h^3 against loads that do not grow, so the residual cannot fall
by 1e-10 of its initial value; before the floor test LEBB and NEBB with 100 elements reported
30 (resp. 300) iterations and converged: false."""

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.numerics.dense import newton
from fxflex.formulation import build
from fxflex.scene import load_scene


def test_linear_system_whose_floor_is_above_rtol_converges_in_one_step():
    rng = np.random.default_rng(3)
    n = 60
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    A = Q @ np.diag(np.logspace(0, 13, n)) @ Q.T        # condition 1e13, like a fine beam
    b = Q @ np.ones(n)                                   # unit load on every mode: x ~ 1
    x, its, hist, ok = newton(lambda x, s: A @ x - s * b, lambda x, s: A, np.zeros(n))
    assert ok
    assert hist[-1] > 1e-10 * hist[0]                    # the relative test alone would fail
    assert its <= 2
    # at the floor: no worse than a backward-stable solve, n eps ||A|| ||x||
    assert hist[-1] <= n * np.finfo(float).eps * np.linalg.norm(A, 2) * np.linalg.norm(x)


def test_no_root_is_still_reported_unconverged():
    """x^2 + 1 = 0 has no real root: the residual stays near 1, far above its floor."""
    x, its, hist, ok = newton(lambda x, s: x**2 + s, lambda x, s: np.diag(2 * x + 1e-300),
                              np.array([0.3]))
    assert not ok
    assert min(hist) > 0.5


@pytest.mark.parametrize("method", ["lebb", "nebb"])
def test_fine_beam_meshes_converge_to_the_coarse_answer(method):
    tips = {}
    for n in (40, 100):
        form = build(method, load_scene(None, [f"mesh.beam_elements={n}"]), MPI.COMM_SELF)
        st = form.steady_state()
        assert st.converged, (n, st.residuals[-3:])
        assert st.iterations <= 8
        tips[n] = st.tip
    # the beams move < 0.1 % of the tip deflection from 10 to 40 elements (docs/beams.md): the
    # floor-stopped iterate is the equilibrium, not a stalled one
    np.testing.assert_allclose(tips[100], tips[40], rtol=0,
                               atol=1e-3 * np.linalg.norm(tips[40]))
