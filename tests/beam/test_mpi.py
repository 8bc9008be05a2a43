"""Replicated beam models: every rank builds the whole model and gets the same answer."""

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.formulation import build
from fxflex.scene import Scene


@pytest.mark.mpi
@pytest.mark.parametrize("method", ["lebb", "nebb", "ancf"])
def test_same_result_on_every_rank(method):
    comm = MPI.COMM_WORLD
    form = build(method, Scene().replace(**{"mesh.beam_elements": 3}), comm)
    assert form.comm.size == 1
    tip = form.steady_state().tip
    spread = comm.allreduce(np.abs(tip - comm.bcast(tip, root=0)).max(), op=MPI.MAX)
    assert spread == 0.0
