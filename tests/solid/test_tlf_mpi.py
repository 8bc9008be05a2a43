"""TLF under MPI: 1000 CD steps (and 100 generalised-alpha steps, with MUMPS on the ranks)
distributed over the ranks match the same run on one process.

Run by the MPI suite (``mpirun -n 2 python -m pytest -m mpi``): every rank builds the problem
twice, once distributed on COMM_WORLD and once whole on COMM_SELF, and compares the tip history
and the final hub-frame displacement field (matched by node coordinates, since the two meshes
number their nodes differently).
"""

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.formulation import BuildOptions
from fxflex.scene import load_scene
from fxflex.scene.kinematics import rotation_z
from fxflex.solid.tlf import TLF
from fxflex.time import simulate

STEPS, DT = 1000, 1.5e-6             # below 2 / w_max of both masses (1.69 us consistent)


def run(comm, force_eval, mass, integrator="cd", dt=DT, steps=STEPS, stats=None):
    scene = load_scene(overrides=["mesh.solid=[20,4,2]"])
    form = TLF(scene, comm, BuildOptions(force_eval=force_eval, mass=mass, need_steady=False))
    state = form.initial_state()
    res = simulate(form, integrator, dt, steps * dt, sample_every=10, keep_history=True,
                   state=state)
    if stats is not None:
        stats.update(res.stats)
    q = state[0]
    x0 = form.model.node_coordinates()
    A = rotation_z(form.drive.angle(res.t))
    U = (x0 + q.reshape(-1, 3)) @ A - x0
    # every rank gets the whole field, rows sorted by node coordinates
    x0, U = np.vstack(comm.allgather(x0)), np.vstack(comm.allgather(U))
    order = np.lexsort(np.round(x0, 9).T[::-1])
    return np.array(res.history), x0[order], U[order], form.dof


@pytest.mark.mpi
@pytest.mark.parametrize("mass", ["lumped", "consistent"])
@pytest.mark.parametrize("force_eval", ["ufl", "invariant"])
def test_two_ranks_match_one_process(force_eval, mass):
    world = run(MPI.COMM_WORLD, force_eval, mass)
    alone = run(MPI.COMM_SELF, force_eval, mass)
    assert world[3] == alone[3]
    # node coordinates (m) gathered from the mesh: the same gmsh points on 1 or 2 ranks, read back
    # to round-off of |x| <= 1.2 m
    np.testing.assert_allclose(world[1], alone[1], rtol=0, atol=1e-12)
    tip_w, tip_s = world[0][:, 1:4], alone[0][:, 1:4]
    tip_err = np.abs(tip_w - tip_s).max() / np.abs(tip_s).max()
    field_err = np.abs(world[2] - alone[2]).max() / np.abs(alone[2]).max()
    if MPI.COMM_WORLD.rank == 0:
        print(f"\n{force_eval}/{mass}: {MPI.COMM_WORLD.size} ranks vs 1 after {STEPS} steps: "
              f"tip {tip_err:.1e}, field {field_err:.1e}")
    assert tip_err <= 1e-8 and field_err <= 1e-8


@pytest.mark.mpi
@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_omega_max_does_not_depend_on_the_partition(mass):
    scene = load_scene(overrides=["mesh.solid=[20,4,2]"])
    w = [TLF(scene, comm, BuildOptions(mass=mass)).omega_max()
         for comm in (MPI.COMM_WORLD, MPI.COMM_SELF)]
    assert w[0] == pytest.approx(w[1], rel=1e-8)


@pytest.mark.mpi
@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_generalized_alpha_on_two_ranks_matches_one_process(mass):
    """100 generalised-alpha steps of 10 us: the same Newton iterations and factorisations, the
    same tip history and final field as on one process."""
    stats_w, stats_s = {}, {}
    world = run(MPI.COMM_WORLD, "ufl", mass, "generalized-alpha", 10e-6, 100, stats_w)
    alone = run(MPI.COMM_SELF, "ufl", mass, "generalized-alpha", 10e-6, 100, stats_s)
    assert stats_w == stats_s and stats_w["steps"] == 100 and stats_w["factorizations"] == 1
    tip_w, tip_s = world[0][:, 1:4], alone[0][:, 1:4]
    tip_err = np.abs(tip_w - tip_s).max() / np.abs(tip_s).max()
    field_err = np.abs(world[2] - alone[2]).max() / np.abs(alone[2]).max()
    assert tip_err <= 1e-8 and field_err <= 1e-8, (tip_err, field_err)
