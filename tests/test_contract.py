"""Every method offers the whole formulation contract (fxflex.formulation, issue 12): the four
Protocols, the declared optional outputs (each None or a working callable, as the table below
says), the rotating analysis through one linearisation type, and ``at()``. Small scenes; under
``mpirun -n 2`` TLF is distributed and the others replicated."""

import math

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.formulation import (FORCE_EVAL, MASS, OUTPUTS, BuildOptions, Dynamics, Formulation,
                                FormulationBase, Implicit, Outputs, RotatingAnalysis,
                                SteadyState, build, dof_count)
from fxflex.scene import METHODS, load_scene

COMM = MPI.COMM_WORLD
SMALL = {"ffrf": ["mesh.solid=[10,2,2]", "reduction.ffrf_modes=12"],
         "gcms": ["mesh.solid=[10,2,2]", "reduction.gcms_modes=36"],
         "tlf": ["mesh.solid=[6,2,2]"], "lebb": [], "nebb": [], "ancf": ["mesh.beam_elements=4"]}
#: the optional outputs each method offers (declared in its class; the rest are None)
OFFERS = {"ffrf": {"extras", "root_stress", "field_writer", "rotating_state"},
          "gcms": {"extras", "root_stress", "field_writer", "rotating_state"},
          "tlf": {"root_stress", "field_writer", "state_points"},
          "lebb": {"extras", "root_stress", "field_writer", "rotating_state"},
          "nebb": {"extras", "root_stress", "field_writer", "rotating_state"},
          "ancf": {"root_stress", "field_writer", "rotating_state"}}

_BUILT: dict = {}


def built(method):
    """One build per method for the module (a TLF build is a few seconds)."""
    if method not in _BUILT:
        scene = load_scene(overrides=SMALL[method] + ["rotation.rpm=3000"])
        _BUILT[method] = (scene, build(method, scene, COMM, BuildOptions()))
    return _BUILT[method]


def test_the_table_covers_every_method():
    assert set(SMALL) == set(OFFERS) == set(METHODS)


@pytest.mark.parametrize("method", METHODS)
def test_the_protocols_and_the_declared_members(method):
    scene, form = built(method)
    for protocol in (Dynamics, Implicit, RotatingAnalysis, Outputs, Formulation):
        assert isinstance(form, protocol), protocol.__name__
    assert isinstance(form, FormulationBase)
    # the solids' options carry the linear solver route build() resolved ("auto": MUMPS fits)
    route = "direct" if method in ("ffrf", "gcms", "tlf") else None
    assert form.method == method and form.scene is scene
    assert form.options == BuildOptions(linear=route)
    # GCMS's count follows the Gram cut, known only once built
    assert isinstance(form.dof, int) and dof_count(method, scene) == (None if method == "gcms"
                                                                      else form.dof)
    assert form.comm.size in (1, COMM.size) and isinstance(form.timings, dict)
    assert all(isinstance(w, str) for w in form.warnings)
    assert form.force_eval == (FORCE_EVAL[method][0] if method in FORCE_EVAL else None)
    assert form.mass_kind in (MASS if method == "tlf" else (None,))
    assert form.deflection_range in ((2.0,) if method in ("tlf", "ancf") else (0.25,))
    assert isinstance(form.extra_columns, tuple)
    assert all(isinstance(c, str) for c in form.extra_columns)
    assert form.probes() == {name: name in OFFERS[method] for name in OUTPUTS}
    for name in OUTPUTS:
        value = getattr(form, name)
        assert (value is None) == (name not in OFFERS[method]) and (value is None or
                                                                    callable(value)), name


@pytest.mark.parametrize("method", METHODS)
def test_the_optional_outputs_work_where_offered(method, tmp_path):
    _, form = built(method)
    q, v = form.initial_state()
    form.constrain(0.0, q, v)
    if form.extras is not None:
        values = form.extras(0.0, q, v)
        assert len(values) == len(form.extra_columns) and all(map(math.isfinite, values))
    else:
        assert form.extra_columns == ()
    if form.root_stress is not None:
        sigma = np.asarray(form.root_stress(0.0, q))
        assert sigma.ndim == 1 and sigma.size and np.isfinite(sigma).all()
    if form.state_points is not None:
        points = form.state_points()
        assert points.shape == (q.size // 3, 3) and np.isfinite(points).all()
    if form.field_writer is not None:
        path = COMM.bcast(str(tmp_path / "u.xdmf") if COMM.rank == 0 else None)
        writer = form.field_writer(path)
        writer.write(0.0, q)
        writer.close()
        assert (tmp_path / "u.xdmf").exists() or COMM.rank != 0


@pytest.mark.parametrize("method", METHODS)
def test_the_rotating_analysis_goes_through_one_linearisation(method):
    _, form = built(method)
    st = form.steady_state()
    assert isinstance(st, SteadyState) and st.converged and np.shape(st.tip) == (3,)
    lin = form.linearise(st)
    assert lin.kind == ("petsc" if method == "tlf" else "dense") and lin.dof > 0
    lam, X = form.rotating_modes(3)
    assert lam.shape == (3,) and X.shape[1] == 3 and np.all(lam.imag >= 0)
    assert np.all(np.diff(np.abs(lam.imag)) >= 0)               # lowest frequency first
    assert form.mode_tip(X).shape == (6, 3)
    assert form.stable(st) is True and form.stability_note is None
    rate, freq = form.growth_rate()
    assert isinstance(rate, float) and isinstance(freq, float) and freq > 0
    assert form.eigenvalues().size >= 3
    w_top, w_rest = form.top_frequency(), form.omega_max()
    assert w_top > 0 and w_rest > 0 and (method != "tlf" or w_top == w_rest)
    # the form keeps one linearisation: the modes above were not computed twice
    assert form.linearisation() is form.linearisation(st)
    lin.destroy()


@pytest.mark.parametrize("method", METHODS)
def test_the_implicit_interface_answers(method):
    _, form = built(method)
    q, v = form.initial_state()
    form.constrain(0.0, q, v)
    f, mx = np.empty_like(q), np.empty_like(q)
    form.force(0.0, q, v, f)
    form.mass_apply(np.ones_like(q), mx)
    factor = form.factorize(0.0, q, v, 1.0, 1e-3, 1e-6)
    out = np.empty_like(q)
    factor.solve(0.0, f, out)
    assert np.isfinite(f).all() and np.isfinite(mx).all() and np.isfinite(out).all()


@pytest.mark.parametrize("method", METHODS)
def test_at_gives_the_same_method_at_another_speed(method):
    scene, form = built(method)
    other = form.at(rpm=5000)
    assert isinstance(other, Formulation) and other.method == method
    assert other.options == form.options and other.scene.rotation.rpm == 5000
    assert other.scene.replace(**{"rotation.rpm": scene.rotation.rpm}) == scene
    assert form.at() is not None and form.at().scene == scene
    damped = form.at(damping=2 * scene.damping.c + 1.0, model="absolute")
    assert damped.scene.damping.model == "absolute" and damped.scene.rotation == scene.rotation
