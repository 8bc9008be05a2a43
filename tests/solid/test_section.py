"""Root-section axial stress of the solid methods against closed forms (uniform beam).

The section forces come from the stress in the root cells integrated against the root nodes'
shape functions: in equilibrium they are the support reaction, so on a uniform cantilever at rest
the corner stress is M c / I to round-off for TLF (Newton equilibrium), and to the modal
truncation for FFRF (30 modes satisfy the equilibrium only in their span).
"""

import math

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.analysis.compare import steady_time
from fxflex.formulation import build
from fxflex.scene import Scene

COMM = MPI.COMM_WORLD
UNIFORM = {"geometry.tip_y": 0.12, "geometry.tip_z": 0.06, "geometry.twist_deg": 0.0,
           "mesh.solid": (20, 4, 2)}
Q, B, H, L = -800.0, 0.12, 0.06, 1.0


def _stress(method, scene):
    form = build(method, scene, COMM)
    st = form.steady_state()
    assert st.converged
    return form.root_stress(steady_time(scene), st.q), form


@pytest.mark.parallel
@pytest.mark.parametrize("method, rtol", [("tlf", 1e-6), ("ffrf", 1e-3)])
def test_cantilever_root_stress_is_mc_over_i(method, rtol):
    scene = Scene().replace(**UNIFORM, **{"rotation.rpm": 0.0, "load.line_load": Q})
    sigma, form = _stress(method, scene)
    ref = abs(Q) * L**2 / 2 * (H / 2) / (B * H**3 / 12)          # 5.556 MPa
    top = form.model.shape.corners(0.0)[:, 1] > 0
    assert np.allclose(sigma[top], ref, rtol=rtol)                  # load along -z: top in tension
    assert np.allclose(sigma[~top], -ref, rtol=rtol)


@pytest.mark.parallel
def test_spinning_bar_root_stress_is_n_over_a():
    """Centrifugal axial force rho Omega^2 A L^2 / 2 at the root of a uniform bar, within the
    root cell layer's own share (h^2 / (3 L^2) = 0.08 % on 20 layers)."""
    scene = Scene().replace(**UNIFORM, **{"rotation.rpm": 1000.0, "load.line_load": 0.0})
    sigma, _ = _stress("tlf", scene)
    w = 1000.0 * math.pi / 30
    ref = scene.material.rho * w**2 * L**2 / 2
    assert np.allclose(sigma, ref, rtol=1.5e-3)
    assert sigma.max() - sigma.min() < 1e-6 * ref                  # no bending
