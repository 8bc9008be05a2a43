"""Closed-form section properties against integration over the solid mesh's sections.

At a layer of nodes x = x_i the section of the mesh is flat and the map (eta, zeta) -> (Y, Z) is
linear, so facet integrals over that layer are exact even with twist: the closed forms must agree
to round-off."""

import numpy as np
import pytest
import ufl
from dolfinx import fem, mesh as dmesh
from mpi4py import MPI

from fxflex.mesh.geometry import BeamShape, saint_venant_rectangle
from fxflex.mesh.solid import build_solid_mesh
from fxflex.scene import load_scene

COMM = MPI.COMM_WORLD
pytestmark = pytest.mark.parallel


def layer_integrals(m, X):
    """int over the mesh's cross-section at X of 1, Y, Z, Z^2, Y^2, Y Z."""
    msh = m.mesh
    facets = dmesh.locate_entities(msh, 2, lambda x: np.isclose(x[0], X))
    tags = dmesh.meshtags(msh, 2, facets, np.full(facets.size, 7, dtype=np.int32))
    lo = COMM.allreduce(msh.geometry.x[:, 0].min(), op=MPI.MIN)
    hi = COMM.allreduce(msh.geometry.x[:, 0].max(), op=MPI.MAX)
    exterior = bool(np.isclose(X, lo) or np.isclose(X, hi))
    md = {"quadrature_degree": 4}
    if exterior:
        d = ufl.Measure("ds", domain=msh, subdomain_data=tags, metadata=md)(7)
    else:
        d = ufl.Measure("dS", domain=msh, subdomain_data=tags, metadata=md)(7)
    x = ufl.SpatialCoordinate(msh)
    Y, Z = x[1], x[2]
    if not exterior:
        Y, Z = Y("+"), Z("+")
    out = []
    for f in (1.0 + 0 * Y, Y, Z, Z * Z, Y * Y, Y * Z):
        out.append(COMM.allreduce(fem.assemble_scalar(fem.form(f * d)), op=MPI.SUM))
    return np.array(out)


@pytest.mark.parametrize("twist", [-45.0, 0.0, 130.0])
def test_section_properties_match_mesh_sections(twist):
    s = load_scene(overrides=[f"geometry.twist_deg={twist}", "geometry.hub_radius=0.25"])
    g = s.geometry
    m = build_solid_mesh(g, (8, 4, 6), COMM)
    shape = BeamShape(g)
    for i in (0, 3, 8):
        x = g.length * i / 8
        p = shape.section(x)
        A, SZ, SY, IY, IZ, IYZ = layer_integrals(m, g.hub_radius + x)
        # closed forms against exact quadrature of the same polynomial integrands: round-off only
        assert A == pytest.approx(float(p.A), rel=1e-12)
        assert abs(SY) < 1e-14 and abs(SZ) < 1e-14
        scale = float(p.J_polar)
        assert IY == pytest.approx(float(p.I_Y), rel=1e-11, abs=1e-13 * scale)
        assert IZ == pytest.approx(float(p.I_Z), rel=1e-11, abs=1e-13 * scale)
        assert IYZ == pytest.approx(float(p.I_YZ), abs=1e-11 * scale)
        assert float(p.J_polar) == pytest.approx(IY + IZ, rel=1e-11)


def test_saint_venant_torsion_constant():
    # square: J = 0.140577 a^4 (Timoshenko & Goodier); thin strip: J -> a c^3 / 3 (1 - 0.63 c/a)
    assert saint_venant_rectangle(1.0, 1.0) == pytest.approx(0.1405770, rel=1e-6)
    assert saint_venant_rectangle(2.0, 1.0) == pytest.approx(0.2287 * 2, rel=2e-3)
    a, c = 100.0, 1.0
    assert saint_venant_rectangle(a, c) == pytest.approx(a * c**3 / 3 * (1 - 0.630 * c / a),
                                                         rel=1e-4)
    assert saint_venant_rectangle(1.0, 3.0) == saint_venant_rectangle(3.0, 1.0)


def test_untwisted_section_is_principal():
    p = BeamShape(load_scene(overrides=["geometry.twist_deg=0"]).geometry).section(
        np.linspace(0, 1, 5))
    assert np.all(p.I_YZ == 0)
    assert p.I_Y[0] == pytest.approx(0.12 * 0.06**3 / 12) and p.I_Z[-1] == pytest.approx(
        0.04 * 0.08**3 / 12)
