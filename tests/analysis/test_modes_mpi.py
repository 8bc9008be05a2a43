"""TLF modes under MPI: the PEP distributed over the ranks gives the roots, labels and tip motions
of the same problem solved whole on each process (COMM_SELF)."""


import numpy as np
import pytest
from mpi4py import MPI

from fxflex.analysis.modes import modes_of
from fxflex.numerics import petsc as pep
from fxflex.formulation import build
from fxflex.scene import load_scene


@pytest.mark.mpi
@pytest.mark.parametrize("model", ["relative", "absolute"])
def test_tlf_modes_two_ranks_match_one_process(model):
    scene = load_scene(overrides=["mesh.solid=[20,4,2]", "rotation.rpm=10000",
                                  f"damping.model=\"{model}\""])
    world = modes_of(build("tlf", scene, MPI.COMM_WORLD), 8)
    alone = modes_of(build("tlf", scene, MPI.COMM_SELF), 8)
    assert MPI.COMM_WORLD.size >= 2
    # each side converged to pep_eigen's tolerance relative to |lambda| on the shift-inverted
    # problem, where these lowest roots are the largest and well separated: 10 x that covers
    # both sides' errors and their condition numbers (a distributed MUMPS factor rounds
    # differently from a serial one)
    tol = pep.TOL                   # pep_eigen's tolerance when none is given
    np.testing.assert_allclose(world.eigenvalues, alone.eigenvalues, rtol=10 * tol)
    assert world.labels == alone.labels and world.stable and alone.stable
    # mode shapes match up to a complex factor: compare normalised tip motions
    for a, b in zip(world.tip.T, alone.tip.T):
        a, b = a / a[np.argmax(np.abs(a))], b / b[np.argmax(np.abs(b))]
        np.testing.assert_allclose(a, b, atol=1e-6)
    # every rank holds the same answer: each compares every rank's roots and labels with its own
    mine = (world.eigenvalues.tolist(), world.labels, world.stable)
    assert all(other == mine for other in MPI.COMM_WORLD.allgather(mine))
