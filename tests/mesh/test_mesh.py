"""The gmsh twisted tapered hex mesh: counts, tags, volume, tip face, cache."""

import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI

from fxflex.mesh.geometry import BeamShape
from fxflex.mesh.solid import ROOT, TIP, build_solid_mesh
from fxflex.scene import load_scene

COMM = MPI.COMM_WORLD
pytestmark = pytest.mark.parallel


def volume(m, degree=None):
    dx = ufl.dx(domain=m.mesh, metadata={} if degree is None else {"quadrature_degree": degree})
    return COMM.allreduce(fem.assemble_scalar(fem.form(1.0 * dx)), op=MPI.SUM)


def test_counts_and_tags():
    g = load_scene().geometry
    m = build_solid_mesh(g, (10, 4, 2), COMM)
    tdim = m.mesh.topology.dim
    assert m.mesh.topology.index_map(tdim).size_global == 10 * 4 * 2
    assert m.mesh.geometry.index_map().size_global == 11 * 5 * 3
    ft = m.facet_tags
    for tag in (ROOT, TIP):
        assert COMM.allreduce(np.count_nonzero(ft.values == tag), op=MPI.SUM) == 4 * 2


def test_untwisted_volume_is_exact():
    g = load_scene(overrides=["geometry.twist_deg=0", "geometry.hub_radius=0.3"]).geometry
    m = build_solid_mesh(g, (7, 2, 4), COMM)
    # an untwisted tapered body is meshed exactly: round-off of the quadrature sum only
    assert volume(m) == pytest.approx(BeamShape(g).volume(), rel=1e-12)


def test_twisted_volume_converges_at_second_order():
    g = load_scene(overrides=["geometry.twist_deg=-90"]).geometry
    exact = BeamShape(g).volume()
    errors = [abs(volume(build_solid_mesh(g, (n, n // 2 * 2, n // 2 * 2), COMM)) - exact) / exact
              for n in (4, 8, 16)]
    orders = np.log2(np.array(errors[:-1]) / errors[1:])
    assert errors[-1] < 2e-3      # -90 deg twist, 16 divisions: measured 1.6e-3
    assert np.all(orders > 1.8) and np.all(orders < 2.3), (errors, orders)


def test_quadratic_geometry_volume_converges_at_fourth_order():
    """27-node hexahedra with every node on the body: the quadratic interpolant of the twisted
    shape (measured 6.2e-5, 3.9e-6, 2.4e-7 at -90 deg; orders 3.99, 4.00)."""
    g = load_scene(overrides=["geometry.twist_deg=-90"]).geometry
    exact = BeamShape(g).volume()
    errors = []
    for n in (4, 8, 16):
        m = build_solid_mesh(g, (n, 2, 2), COMM, order=2)
        assert m.order == 2 and m.mesh.geometry.cmap.degree == 2
        errors.append(abs(volume(m, 6) - exact) / exact)
    orders = np.log2(np.array(errors[:-1]) / errors[1:])
    assert np.all(orders > 3.8) and np.all(orders < 4.2), (errors, orders)


def test_tip_face_nodes_lie_on_the_twisted_tapered_rectangle():
    s = load_scene(overrides=["geometry.hub_radius=0.2"])
    g, shape = s.geometry, BeamShape(s.geometry)
    ny, nz = 6, 4
    m = build_solid_mesh(g, (5, ny, nz), COMM)
    x = m.mesh.geometry.x
    tip = x[np.isclose(x[:, 0], g.hub_radius + g.length)]
    b, h, th = shape.sizes(g.length)
    # back to the section's own axes: y~ = c Y + s Z, z~ = -s Y + c Z
    c, sn = np.cos(th), np.sin(th)
    yt, zt = c * tip[:, 1] + sn * tip[:, 2], -sn * tip[:, 1] + c * tip[:, 2]
    j, k = (yt / b + 0.5) * ny, (zt / h + 0.5) * nz
    # gmsh places the nodes on the section's grid to its geometric tolerance (1e-9 m scale)
    assert np.allclose(j, np.round(j), atol=1e-9) and np.allclose(k, np.round(k), atol=1e-9)
    assert j.min() > -1e-9 and j.max() < ny + 1e-9 and k.min() > -1e-9 and k.max() < nz + 1e-9
    n_tip = COMM.allreduce(len({(round(a), round(bb)) for a, bb in zip(j, k)}), op=MPI.SUM)
    assert n_tip >= (ny + 1) * (nz + 1)          # ghosts may repeat a node across ranks


@pytest.mark.serial
def test_cache_hit_and_invalidation(tmp_path, monkeypatch):
    monkeypatch.setenv("FXFLEX_CACHE", str(tmp_path))
    g = load_scene().geometry
    a = build_solid_mesh(g, (4, 2, 2), MPI.COMM_SELF)
    b = build_solid_mesh(g, (4, 2, 2), MPI.COMM_SELF)
    assert a.generated and not b.generated and a.path == b.path and a.path.exists()
    assert np.allclose(np.sort(a.mesh.geometry.x, axis=0), np.sort(b.mesh.geometry.x, axis=0),
                       rtol=0, atol=1e-15)
    g2 = load_scene(overrides=["geometry.twist_deg=-30"]).geometry
    c = build_solid_mesh(g2, (4, 2, 2), MPI.COMM_SELF)
    assert c.generated and c.path != a.path
    assert build_solid_mesh(g, (4, 2, 4), MPI.COMM_SELF).generated
