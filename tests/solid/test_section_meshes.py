"""Solid meshes of sections other than the paper's rectangle (SPEC section 9, issue 14 item 2):
their volume, the loads and tip probe on them, and FFRF / TLF against the beam on the same
section (an ellipse cantilever; a slender NACA 0012 blade: tip forces, frequencies, torsion)."""

import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI

from fxflex.formulation import build
from fxflex.mesh.section_mesh import stretch
from fxflex.mesh.solid import ROOT, build_solid_mesh
from fxflex.scene import Scene
from fxflex.solid.model import SolidModel
from fxflex.solid.small_strain import linear_steady

COMM = MPI.COMM_WORLD
#: a slender uniform elliptic cantilever (L / b = 12.5), at rest, loaded at the tip
CANTILEVER = {"geometry.section": "ellipse", "geometry.root_y": 0.08, "geometry.tip_y": 0.08,
              "geometry.root_z": 0.04, "geometry.tip_z": 0.04, "geometry.twist_deg": 0.0,
              "rotation.rpm": 0.0, "load.line_load": 0.0, "load.tip_force": (0.0, 0.0, -1000.0)}
NACA = {"geometry.section": "naca4", "geometry.airfoil": "2412"}


def _scene(**keys) -> Scene:
    return Scene().replace(**keys)


def _integral(mesh, form) -> float:
    return COMM.allreduce(fem.assemble_scalar(fem.form(form)))


def _root_area(sm) -> float:
    ds = ufl.Measure("ds", domain=sm.mesh, subdomain_data=sm.facet_tags)
    return _integral(sm.mesh, 1.0 * ds(ROOT))


@pytest.mark.parametrize("section", ["ellipse", "naca4"])
def test_volume_is_the_sections_to_the_polygon_error(section):
    """Untwisted and tapered: every section of the Q1 mesh is its root polygon (the quads'
    boundary chords) stretched by s_y s_z, exactly (the trilinear map of linearly scaled nodes),
    so the volume is A_h(0) int s_y s_z dx to round-off. A_h(0) is inside the outline by the
    chords' segments: for the ellipse (semi-axes a, b) they are exactly a b (D - sin D) / 2 for
    chords spanning D of the ellipse's parameter angle, so A_h + that sum is pi a b to the
    splines' error; the airfoil's falls with refinement. Q2 puts the chords' midpoints on the
    outline: its volume error is below 5 % of Q1's on the same mesh."""
    scene = _scene(**{"geometry.section": section, "geometry.twist_deg": 0.0})
    errors = []
    for ny, nz in ((6, 2), (12, 4), (24, 8)):
        sm = build_solid_mesh(scene.geometry, (4, ny, nz), COMM, use_cache=False)
        shape = sm.shape
        area_h = _root_area(sm)
        xs = np.linspace(0.0, shape.L, 3)           # s_y s_z is quadratic: Simpson is exact
        sy, sz, _ = stretch(shape, xs)
        exact = area_h * shape.L / 6 * (sy[0] * sz[0] + 4 * sy[1] * sz[1] + sy[2] * sz[2])
        assert _integral(sm.mesh, 1.0 * ufl.dx(domain=sm.mesh)) == pytest.approx(exact,
                                                                                 rel=1e-12)
        errors.append(area_h / float(shape.section(np.array(0.0)).A) - 1)
        if section == "ellipse":
            a, b = scene.geometry.root_y / 2, scene.geometry.root_z / 2
            p = np.vstack(COMM.allgather(sm.mesh.geometry.x))
            p = p[np.abs(p[:, 0]) < 1e-12]
            r = np.hypot(p[:, 1] / a, p[:, 2] / b)
            t = np.unique(np.round(np.arctan2(p[r > 1 - 1e-6, 2] / b, p[r > 1 - 1e-6, 1] / a),
                                   12))
            D = np.diff(np.append(t, t[0] + 2 * np.pi))
            segments = a * b * np.sum(D - np.sin(D)) / 2
            assert area_h + segments == pytest.approx(np.pi * a * b, rel=1e-6)
    errors = np.array(errors)
    assert np.all(errors < 0), errors                    # chords inside a convex outline
    assert np.all(np.abs(errors[1:]) < np.abs(errors[:-1]) / 2), errors
    sm = build_solid_mesh(scene.geometry, (4, 6, 2), COMM, use_cache=False, order=2)
    xs = np.linspace(0.0, shape.L, 3)
    A = shape.section(xs).A                             # quadratic in x: Simpson is exact
    reference = shape.L / 6 * (A[0] + 4 * A[1] + A[2])
    volume = _integral(sm.mesh, 1.0 * ufl.dx(domain=sm.mesh))
    assert abs(volume / reference - 1) < 0.05 * abs(errors[0]), (volume / reference - 1, errors)


def test_line_load_resultant_and_tip_probe():
    """The line load on another section is q / A(X) along z over the volume: its resultant is
    q L (the interpolated 1 / A is exact at the nodes; twisted, the cells' section between
    levels deviates at second order in the twist per layer: 2.25 deg here, measured 1e-5); a
    uniform translation is probed exactly at the tip."""
    scene = _scene(**NACA, **{"mesh.solid": (20, 8, 2)})
    model = SolidModel(scene, COMM)
    b = model.line_load_vector().getArray()[: model.n_owned].reshape(-1, 3)
    total = COMM.allreduce(b.sum(axis=0))
    q, L = scene.load.line_load, scene.geometry.length
    # the clamped root nodes' share (zeroed) is about q h / 2 of q L: add it back
    h = L / scene.mesh.solid[0]
    assert total[2] == pytest.approx(q * (L - h / 2), rel=0.02 * h / L)
    assert abs(total[0]) + abs(total[1]) < 1e-12 * abs(q * L)
    shift = np.array([1.0, -2.0, 3.0])
    u = np.tile(shift, model.n_owned_nodes)
    assert model.tip_displacement(u) == pytest.approx(shift, rel=1e-12)
    U = np.column_stack([u, 2 * u])
    assert model.tip_displacement(U)[:, 1] == pytest.approx(2 * shift, rel=1e-12)


def test_ffrf_tlf_cantilever_against_the_beam():
    """Slender uniform ellipse (L / b = 12.5, L / h = 25), tip force along z: Q2 FFRF (the
    full-order linear equilibrium), the FFRF and GCMS formulations and TLF approach LEBB on the same
    section. Beam theory's own error here: the shear deflection 3 E I / (k G A L^2) ~ 1e-3
    (more flexible) and the clamped root's held Poisson contraction (stiffer), of the same order.
    Measured gap to LEBB: -1.7 % (10 x 4 x 2), -0.62 % (20 x 8 x 4), -0.43 % (40 x 16 x 8).
    Q1 locks: -44 % (20 x 8 x 4), -17 % (40 x 16 x 8)."""
    lebb = build("lebb", _scene(**CANTILEVER), COMM).steady_state().tip[2]
    gaps = []
    for div in ((10, 4, 2), (20, 8, 4)):
        scene = _scene(**CANTILEVER, **{"mesh.solid": div, "mesh.solid_degree": 2})
        model = SolidModel(scene, COMM)
        lin = linear_steady(model, 0.0).tip[2]
        tlf = build("tlf", scene, COMM).steady_state().tip[2]
        # a 0.25 % tip deflection: TLF's geometric nonlinearity is 1e-5 of it
        assert tlf == pytest.approx(lin, rel=1e-4)
        gaps.append(lin / lebb - 1)
    for method in ("ffrf", "gcms"):                      # 30 clamped modes; 90 component modes
        assert build(method, scene, COMM).steady_state().tip[2] == pytest.approx(lin, rel=1e-3)
    assert abs(gaps[1]) < abs(gaps[0]) / 2, gaps
    assert abs(gaps[1]) < 0.01, gaps


#: a slender uniform NACA 0012 blade, L / chord = 10, at rest, untwisted, Poisson's ratio 0
SLENDER_AIRFOIL = {"geometry.section": "naca4", "geometry.airfoil": "0012",
                   "geometry.root_y": 0.1, "geometry.tip_y": 0.1, "geometry.root_z": 0.012,
                   "geometry.tip_z": 0.012, "geometry.twist_deg": 0.0, "rotation.rpm": 0.0,
                   "load.line_load": 0.0, "damping.c": 0.0, "material.nu": 0.0,
                   "mesh.beam_elements": 40, "reduction.ffrf_modes": 8}


def test_slender_airfoil_solid_against_the_beam_at_rest():
    """NACA 0012, chord 0.1 m, L = 1 m, tip forces along Y (edge) and Z (flap), the first flap and
    edge frequencies and the first torsion: the linear solid (Q2 10 x 4 x 2 and 20 x 4 x 2; its
    full-order equilibrium and FFRF's clamped modes) against LEBB on the same computed section.
    With nu = 0 the clamped root holds no Poisson contraction, so beam theory's error is its
    shear term 6 I / (k A L^2) (G = E / 2; k between 2/3 and 1 for a solid section): flap
    (I_Y, thin) 7e-5, edge (I_Z) 0.33-0.49 %. Flap tip and frequency: within the change
    between the two meshes (the finer mesh's error, order >= 1) plus the shear term; edge tip:
    more flexible by the shear term within that change. Torsion: the solid is stiffer (its
    clamped root restrains the section's warping; docs/sections.md measures the gap halving
    with L / chord). Measured: flap +3.1e-4, flap frequency +1.1e-4, edge +0.46 %, torsion
    +2.0 % on 20 x 4 x 2 (with nu = 0.28 the root's held Poisson contraction adds -0.77 % in
    flap on 40 x 16 x 4, also halving with L / chord)."""
    from fxflex.analysis.modes import modes_of
    from fxflex.section.blade import Blade
    from fxflex.section.properties import analyse

    def first(form) -> dict[str, float]:
        m = modes_of(form, 6)
        return {label: float(f) for f, label in reversed(list(zip(m.frequencies_hz, m.labels)))}

    force = {"load.tip_force": (0.0, -1000.0, -100.0)}
    beam = build("lebb", _scene(**SLENDER_AIRFOIL, **force), None).steady_state().tip
    beam_f = first(build("lebb", _scene(**SLENDER_AIRFOIL), None))
    tips, freqs = [], []
    for div in ((10, 4, 2), (20, 4, 2)):
        mesh = {"mesh.solid": div, "mesh.solid_degree": 2}
        tips.append(linear_steady(SolidModel(_scene(**SLENDER_AIRFOIL, **mesh, **force), COMM),
                                  0.0).tip)
        freqs.append(first(build("ffrf", _scene(**SLENDER_AIRFOIL, **mesh), COMM)))
    sec = analyse(Blade(_scene(**SLENDER_AIRFOIL).geometry).outline(0.0))
    shear = {axis: 6.0 * inertia / (sec.A * 1.0**2) for axis, inertia in (("Y", sec.Iy),
                                                                          ("Z", sec.Iz))}
    flap, flap_change = tips[1][2] / beam[2] - 1.0, abs(tips[1][2] - tips[0][2]) / abs(beam[2])
    assert abs(flap) < flap_change + 1.5 * shear["Y"]
    fl = [f["out-of-plane"] for f in freqs]
    assert abs(fl[1] / beam_f["out-of-plane"] - 1.0) < (abs(fl[1] - fl[0]) / fl[1]
                                                        + 1.5 * shear["Y"])
    edge, edge_change = tips[1][1] / beam[1] - 1.0, abs(tips[1][1] - tips[0][1]) / abs(beam[1])
    assert shear["Z"] - edge_change < edge < 1.5 * shear["Z"] + edge_change
    assert freqs[1]["torsion"] > beam_f["torsion"]
    print(f"\nflap {flap:+.2e} (change {flap_change:.1e}), edge {edge:+.2e} (shear "
          f"{shear['Z']:.2e}..{1.5 * shear['Z']:.2e}), torsion "
          f"{freqs[1]['torsion'] / beam_f['torsion'] - 1:+.2e}")


def test_tlf_steady_on_a_naca_blade_serial_numbers():
    """TLF's rotating equilibrium at 1000 rpm on the tapered, twisted NACA 2412 blade under the
    paper's line load (Q1, 20 x 8 x 2: locked, about a third of NEBB's deflection). Distributed
    (mpirun -n 2) it gives the serial numbers."""
    scene = _scene(**NACA, **{"mesh.solid": (20, 8, 2)})
    st = build("tlf", scene, COMM).steady_state()
    assert st.converged
    tip = np.asarray(st.tip)
    assert tip[2] < 0 and np.all(np.isfinite(tip))
    if COMM.size > 1:
        serial = np.asarray(build("tlf", scene, MPI.COMM_SELF).steady_state().tip)
        assert tip == pytest.approx(serial, rel=1e-8, abs=1e-12)
