"""``form.at(rpm=, damping=, model=)`` (fxflex.formulation.Formulation.at): the same method at
another speed or damping gives the numbers of a fresh build of that scene, bit for bit, and FFRF
and GCMS share their projections, mesh, operators and clamped modes with the build they came
from rather than computing them again."""

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.formulation import METHODS, build, rescene
from fxflex.scene import load_scene
from fxflex.solid.family import ReducedFamily

COMM = MPI.COMM_WORLD
#: solids on a coarse mesh: TLF's steady state in seconds
COARSE = "mesh.solid=[10, 2, 2]"


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """The coarse scene, with one cache folder for the module, the same on every rank (rank 0's:
    the fresh builds read the projections the first build wrote, as a user's second run does;
    a folder per rank would make them recompute the clamped modes, equal only to round-off)."""
    folder = COMM.bcast(str(tmp_path_factory.mktemp("cache")) if COMM.rank == 0 else None)
    with pytest.MonkeyPatch.context() as env:
        env.setenv("FXFLEX_CACHE", folder)
        env.delenv("FXFLEX_NO_CACHE", raising=False)
        yield load_scene(overrides=[COARSE])


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("change", [{"rpm": 5000.0}, {"damping": 20.0, "model": "absolute"}])
def test_at_equals_a_fresh_build(base, method, change, distributed_rtol):
    form = build(method, base, COMM)
    other = form.at(**change)
    fresh = build(method, rescene(base, **change), COMM)
    assert other.scene == fresh.scene
    assert other.method == method and other.options == form.options
    # bit for bit where the solve is repeatable; TLF on several ranks to its solver's accuracy
    st = fresh.steady_state()
    rtol = distributed_rtol(fresh, st) if fresh.distributed else 0.0
    np.testing.assert_allclose(other.steady_state().tip, st.tip, rtol=rtol, atol=0.0)
    assert not np.array_equal(other.steady_state().tip, form.steady_state().tip)
    if form.all_roots:
        np.testing.assert_array_equal(other.eigenvalues(), fresh.eigenvalues())


@pytest.mark.parametrize("method", ["ffrf", "gcms"])
def test_reduced_at_shares_projections_mesh_and_modes(base, method):
    form = build(method, base, COMM)
    other = form.at(rpm=5000.0).at(damping=10.0)
    assert other._projected is form._projected
    # the mesh, operators and modes are built once, by whichever asks first, for both
    assert other.model is form.model
    assert other.data is form.data and other.modes is form.modes
    q = np.linspace(-1e-4, 1e-4, form.dof)      # at t = 0 the hub angle is 0 at any speed
    np.testing.assert_array_equal(other.root_stress(0.0, q), form.root_stress(0.0, q))
    assert other._root_resultants() is form._root_map


def test_family_builds_share_through_at(base):
    family = ReducedFamily(base, COMM, count=30)
    a = family.build("gcms", "rotation.rpm=1000")
    b = family.build("gcms", "rotation.rpm=5000", "damping.c=10")
    c = family.build("gcms", "rotation.rpm=5000", "reduction.gcms_modes=60")
    assert b._projected is a._projected and c._projected is not a._projected
    assert a.model is family.model and b.model is family.model
    fresh = build("gcms", b.scene, COMM)
    np.testing.assert_allclose(b.steady_state().tip, fresh.steady_state().tip, rtol=1e-9)
