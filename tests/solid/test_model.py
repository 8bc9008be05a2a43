"""Loads, clamp and tip probe of the shared solid model (SPEC sections 1-2), on any rank count."""

import numpy as np
import pytest
from dolfinx import fem
from mpi4py import MPI

from fxflex.scene import load_scene
from fxflex.solid.model import SolidModel, solid_dof_count

COMM = MPI.COMM_WORLD
pytestmark = pytest.mark.parallel


@pytest.fixture(scope="module")
def model():
    s = load_scene(overrides=["mesh.solid=[10,4,2]", "geometry.hub_radius=0.4",
                              "load.tip_force=[1.5,-2.0,3.0]"])
    return SolidModel(s, COMM)


def owned_sum(vec, comp):
    arr = vec.getArray()
    return COMM.allreduce(arr[comp::3].sum(), op=MPI.SUM)


def test_dof_count(model):
    assert model.dof == solid_dof_count(model.scene) == 3 * 10 * 5 * 3


def test_line_load_is_consistent(model):
    b = model.line_load_vector()
    q, L, h = model.scene.load.line_load, model.scene.geometry.length, 0.1
    # consistent nodal forces sum to q L; the root node's share (q h / 2) goes into the clamp
    # a sum of a few hundred exact quadrature weights: round-off ~ n eps
    assert owned_sum(b, 2) == pytest.approx(q * (L - h / 2), rel=1e-13)
    assert owned_sum(b, 0) == 0 and owned_sum(b, 1) == 0
    arr = b.getArray()
    tip = model.tip_node
    if tip is not None:
        assert arr[3 * tip + 2] == pytest.approx(q * h / 2, rel=1e-13)


def test_tip_traction_is_one_newton(model):
    for i, vec in enumerate(model.tip_traction_vectors()):
        for comp in range(3):
            assert owned_sum(vec, comp) == pytest.approx(1.0 if comp == i else 0.0, abs=1e-13)
    total = model.rotating_load()
    f = model.scene.load.tip_force
    assert owned_sum(total, 0) == pytest.approx(f[0], rel=1e-12)
    assert owned_sum(total, 1) == pytest.approx(f[1], rel=1e-12)


@pytest.mark.mpi
def test_tip_probe_under_mpi_sees_one_node(model):
    """The tip centre lives on one rank; every rank must see its displacement."""
    assert COMM.allreduce(int(model.tip_node is not None), op=MPI.SUM) == 1
    test_tip_probe(model)


def test_tip_probe(model):
    u = fem.Function(model.V)
    u.interpolate(lambda x: np.vstack([x[0], 2 * x[0] + x[1], -3 * x[0] + x[2]]))
    tip = model.tip_displacement(u.x.array)
    R_L = model.scene.geometry.hub_radius + model.scene.geometry.length
    # a linear field interpolated exactly and probed at a node: round-off only
    assert np.allclose(tip, [R_L, 2 * R_L, -3 * R_L], rtol=1e-14)
    # rigid rotation by phi: x = A x0, so the rotating-frame deflection is zero
    phi = 0.7
    c, s = np.cos(phi), np.sin(phi)
    u.interpolate(lambda x: np.vstack([(c - 1) * x[0] - s * x[1], s * x[0] + (c - 1) * x[1],
                                       0 * x[2]]))
    assert np.allclose(model.tip_relative(u.x.array, phi), 0.0, atol=1e-15)
