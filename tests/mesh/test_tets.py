"""Imported tetrahedral meshes of the default blade (issue 14, SPEC section 9): TLF and FFRF run
on 4- and 10-node tetrahedra, quadratic tetrahedra agree with Q2 hexahedra to the two sides'
discretisation errors, HRZ gives central difference a positive lumped mass, and the mode shapes'
span stations exist between the root and tip planes.

The meshes are :func:`fxflex.mesh.tetra.write_tet_blade` files written once per module into
tmp_path; the hexahedral side is the built-in mesh of the rectangle given as a polygon section,
which uses the imported meshes' load and tip conventions (:mod:`fxflex.bench.tets`).
Discretisation errors quoted below are from ``python -m fxflex.bench.tets --sizes
0.06,0.05 --levels 1,2,3`` (docs/sections.md): tip deflection against the Q2 Richardson
extrapolation, P2 tetrahedra of size 0.05 2.9e-3, Q2 16x4x4 2.7e-3; the four lowest
frequencies, P2 size 0.05 within 0.03 % and Q2 16x4x4 within 0.1 % of Q2 24x6x6."""

import numpy as np
import pytest
from dolfinx import fem
from mpi4py import MPI

from fxflex.analysis.modes import modes_of
from fxflex.formulation import BuildOptions, build
from fxflex.mesh.geometry import BeamShape
from fxflex.bench.tets import hex_scene, tet_scene
from fxflex.scene import Scene
from fxflex.solid.lumping import hrz_lumped_mass
from fxflex.solid.model import SolidModel
from fxflex.time import simulate
from fxflex.time.step_stability import critical_step

COMM = MPI.COMM_WORLD
SIZE = 0.05             # 3543 unknowns as P2, 0.2 s per steady state
RPM = 1000.0


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return COMM.bcast(tmp_path_factory.mktemp("tets") if COMM.rank == 0 else None, root=0)


@pytest.fixture(scope="module")
def tets(folder):
    from fxflex.mesh.tetra import write_tet_blade

    paths = {order: folder / f"blade-p{order}.msh" for order in (1, 2)}
    if COMM.rank == 0:
        for order, path in paths.items():
            write_tet_blade(Scene().geometry, path, SIZE, order)
    COMM.barrier()                                   # the scene checks that the file exists
    return {order: tet_scene(path, order, RPM) for order, path in paths.items()}


@pytest.fixture(scope="module")
def hexes(folder):
    return hex_scene(folder, 2, RPM)                   # Q2 16x4x4


def _relative(a, b):
    return float(np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(b))


def test_p2_tets_agree_with_q2_hexahedra(tets, hexes):
    """TLF steady state and frequencies at 1000 rpm: the gap is bounded by the sum of both
    sides' errors (module docstring: 5.6e-3 for the tip, 0.13 % for the frequencies), doubled
    because the tetrahedra's estimate comes from two unstructured meshes. P1 tetrahedra run
    too, locked (stiffer than P2, as Q1 is than Q2: a smaller deflection, higher frequencies)."""
    tlf = {order: build("tlf", scene, COMM) for order, scene in tets.items()}
    tip = {order: form.steady_state().tip for order, form in tlf.items()}
    ref_form = build("tlf", hexes, COMM)
    ref = ref_form.steady_state().tip
    assert _relative(tip[2], ref) < 2 * 5.6e-3
    assert np.linalg.norm(tip[1]) < np.linalg.norm(tip[2])
    mine, theirs = modes_of(tlf[2], 4), modes_of(ref_form, 4)
    assert mine.stable and mine.labels == theirs.labels
    gaps = np.asarray(mine.frequencies_hz) / np.asarray(theirs.frequencies_hz) - 1.0
    assert np.all(np.abs(gaps) < 2 * 1.3e-3)
    locked = modes_of(tlf[1], 2)
    assert locked.labels == mine.labels[:2]
    assert np.all(np.asarray(locked.frequencies_hz) > np.asarray(mine.frequencies_hz[:2]))


def test_ffrf_frequencies_on_p2_tets(tets, hexes):
    """FFRF (clamped modes, then the rotating reduced model) on the tetrahedra against FFRF on
    the hexahedra, the same bound as TLF's frequencies."""
    opts = {"reduction.ffrf_modes": 6}
    mine = modes_of(build("ffrf", tets[2].replace(**opts), COMM), 4)
    theirs = modes_of(build("ffrf", hexes.replace(**opts), COMM), 4)
    assert mine.labels == theirs.labels
    gaps = np.asarray(mine.frequencies_hz) / np.asarray(theirs.frequencies_hz) - 1.0
    assert np.all(np.abs(gaps) < 2 * 1.3e-3)


def test_hrz_masses_are_positive_and_sum_to_the_body(tets):
    """The row sums of 10-node tetrahedra go negative at the vertices (-rho V_e / 20); HRZ's
    entries are positive and add up to int rho dV over the mesh (the same quadrature: round-off)
    and to rho times the exact volume within the quadratic geometry's error (h^4; measured 2e-9
    at size 0.03, bounded here by 1e-6). On 4-node tetrahedra HRZ equals the row sums."""
    model = SolidModel(tets[2], COMM)
    assert model.hrz_lumping
    row = model.vector(model.lumped_mass_form(), zero_clamped=False).getArray()[: model.n_owned]
    assert COMM.allreduce(float(row.min()), op=MPI.MIN) < 0.0
    m = model.lumped_mass()
    assert COMM.allreduce(float(m.min()), op=MPI.MIN) > 0.0
    total = COMM.allreduce(float(m.sum())) / 3.0
    mesh_mass = COMM.allreduce(fem.assemble_scalar(fem.form(model.rho * model.dx)))
    assert abs(total - mesh_mass) < 1e-12 * mesh_mass
    exact = model.rho * BeamShape(model.scene.geometry).volume()
    assert abs(total - exact) < 1e-6 * exact
    # the element diagonals are read in the continuous space's local order
    cells = model.mesh.topology.index_map(3).size_local
    W = fem.FunctionSpace(model.mesh, ("DG", 2))
    dg = W.dofmap.list.array.reshape(cells_total(model), -1)[:cells]
    cg = model.V.dofmap.list.array.reshape(cells_total(model), -1)[:cells]
    np.testing.assert_allclose(W.tabulate_dof_coordinates()[dg],
                               model.V.tabulate_dof_coordinates()[cg], rtol=0, atol=1e-12)
    linear = SolidModel(tets[1], COMM)
    row1 = linear.vector(linear.lumped_mass_form(), zero_clamped=False).getArray()
    np.testing.assert_allclose(hrz_lumped_mass(linear), row1[: linear.n_owned], rtol=1e-12)


def cells_total(model) -> int:
    imap = model.mesh.topology.index_map(3)
    return imap.size_local + imap.num_ghosts


def test_central_difference_on_p2_tets_is_stable_at_the_computed_step(tets):
    """TLF with the HRZ mass: the critical step from w_max (SLEPc, 1e-8) and the damping law of
    :func:`critical_step` bounds central difference sharply. At 0.98 of it 1000 steps stay
    bounded; at 1.05 of it the top mode grows by about 1.9 per step (|z| for z + 1/z =
    2 - (h w)^2) and the run diverges within the same 1000 steps (measured: 0.99 stable, 1.01
    non-finite within 100 steps)."""
    form = build("tlf", tets[2], COMM, BuildOptions(need_steady=False, mass="lumped"))
    dt = critical_step("cd", form.omega_max(), form.scene.damping.c / form.scene.material.rho)
    stable = simulate(form, "cd", 0.98 * dt, 1000 * 0.98 * dt, sample_every=100)
    assert stable.diverged is None and np.all(np.isfinite(stable.tip))
    unstable = simulate(form, "cd", 1.05 * dt, 1000 * 1.05 * dt, sample_every=100)
    assert unstable.diverged is not None


def test_mode_shapes_have_stations_between_root_and_tip(tets, hexes):
    """span_sections on the tetrahedra: the root and tip planes are node layers, the nodes in
    between fill slabs; the stations run from 0 to L, the root station does not move, the tip
    station is the tip probe (the rigid fit over the tip face's nodes against the face's
    area-weighted mean: they differ by the mode's deformation over the face, measured 9e-7 of
    the tip motion, bounded by 1e-4), and the first bending shape follows the hexahedra's
    (interpolated to the tet stations) to the two meshes' discretisation error (about 1e-3 in
    the frequencies) plus the slab fit's, O((w / L)^2) for slabs of width w ~ L / 30: measured
    4e-4 of the normalised shape, bounded by 5e-3."""
    form = build("tlf", tets[2], COMM)
    _, X = form.rotating_modes(2)
    x, S = form.mode_span(X)
    L = form.scene.geometry.length
    assert x[0] == 0.0 and abs(x[-1] - L) < 1e-12 and np.all(np.diff(x) > 0)
    assert x.size > 10
    np.testing.assert_array_equal(S[:, 0], 0.0)
    tip = form.mode_tip(X)[:4]
    assert np.max(np.abs(S[:, -1] - tip)) < 1e-4 * np.max(np.abs(tip))
    ref = build("tlf", hexes, COMM)
    _, Xr = ref.rotating_modes(2)
    xr, Sr = ref.mode_span(Xr)

    def shape(S, j):
        w = S[2, :, j] / S[2, -1, j]                  # out-of-plane, scaled to 1 at the tip
        return np.real(w)

    np.testing.assert_allclose(shape(S, 0), np.interp(x, xr, shape(Sr, 0)), atol=5e-3)
