"""The public Python API (fxflex.api through ``import fxflex``): it is light to import, every
name resolves, and its numbers are those of the functions underneath (and of the CLI)."""

import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from mpi4py import MPI

import fxflex
from fxflex import api
from fxflex.analysis.modes import modes_of
from fxflex.formulation import BuildOptions, build, default_integration
from fxflex.io.series import read_series
from fxflex.scene import Scene, load_scene
from fxflex.time import diagnose, simulate
from fxflex.time.driver import step_to_end

ROOT = pathlib.Path(__file__).parents[1]
DEMO = ROOT / "demos" / "api_quickstart.py"
SOLID = ["mesh.solid=[10,2,2]"]


def test_every_public_name_resolves_to_its_source():
    for name in fxflex.__all__:
        assert getattr(fxflex, name) is not None, name
    lazy = {n for n, where in fxflex._LAZY.items() if where == "fxflex.api"}
    assert lazy == set(api.__all__)
    assert fxflex.build is api.build and fxflex.SceneError is api.SceneError
    assert fxflex.RunResult.__module__ == "fxflex.time.driver"
    assert set(fxflex.__all__) <= set(dir(fxflex))
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        fxflex.nothing


@pytest.mark.serial
def test_import_is_light_and_beams_never_import_dolfinx():
    code = ("import sys, fxflex; light = sorted(m for m in ('fxflex.api', 'numpy', 'mpi4py', "
            "'dolfinx') if m in sys.modules); "
            "form = fxflex.build('lebb', fxflex.load_scene()); fxflex.run(form, 1e-4); "
            "fxflex.modes(form, 2); print(light, 'dolfinx' in sys.modules)")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stdout.split() == ["[]", "False"]


def test_beam_build_steady_stability_modes_equal_the_formulation_s():
    scene = load_scene(overrides=["rotation.rpm=5000"])
    form = fxflex.build("nebb", scene, force_eval="element")
    ref = build("nebb", scene, MPI.COMM_WORLD, BuildOptions(force_eval="element"))
    assert form.options == ref.options and form.force_eval == "element"
    st, st_ref = fxflex.steady(form), ref.steady_state()
    assert np.array_equal(st.tip, st_ref.tip) and st.iterations == st_ref.iterations
    assert fxflex.stability(form) == (True, None)
    m, m_ref = fxflex.modes(form, 4), modes_of(ref, 4)
    assert np.array_equal(m.eigenvalues, m_ref.eigenvalues) and m.labels == m_ref.labels
    assert isinstance(m, fxflex.Modes) and isinstance(form, fxflex.Formulation)
    assert fxflex.info(scene, ["nebb"]) == {"nebb": {"description": fxflex.info()["nebb"][
        "description"], "dof": ref.dof}}


def test_run_equals_simulate_with_the_paper_s_defaults():
    form = fxflex.build("lebb")
    res = fxflex.run(form, 1e-3)
    assert isinstance(res, fxflex.RunResult) and res.diverged is None
    integrator, dt = default_integration("lebb", None, None, form.scene.rotation.rpm)
    assert (integrator, dt) == ("ab2", 0.4e-6)
    dt, n = step_to_end(1e-3, dt)
    ref = simulate(build("lebb", Scene(), MPI.COMM_WORLD), integrator, dt, 1e-3, sample_every=n)
    assert res.steps == ref.steps == 2500 and res.t == ref.t
    assert np.array_equal(res.tip, ref.tip)
    alpha = fxflex.run(form, 1e-3, integrator="generalized-alpha", history=True)
    ref = simulate(form, "generalized-alpha", 20e-6, 1e-3, keep_history=True, rho_inf=0.9,
                   sample_every=1)
    assert np.array_equal(alpha.tip, ref.tip) and alpha.steps == 50
    assert np.array_equal(np.array(alpha.history), np.array(ref.history))


def test_run_options_are_checked_with_the_cli_s_messages():
    form = fxflex.build("lebb")
    with pytest.raises(fxflex.FxflexError, match="rho_inf: only applies"):
        fxflex.run(form, 1e-4, rho_inf=0.5)
    with pytest.raises(fxflex.FxflexError, match=r"rho_inf: must lie in \[0, 1\]"):
        fxflex.run(form, 1e-4, integrator="generalized-alpha", rho_inf=1.5)
    with pytest.raises(fxflex.FxflexError, match="--dt: required with --integrator cd"):
        fxflex.run(form, 1e-4, integrator="cd")
    with pytest.raises(fxflex.FxflexError, match="t_end: must be > 0"):
        fxflex.run(form, 0.0)
    with pytest.warns(UserWarning, match="shortened"):
        res = fxflex.run(form, 1e-4, dt=0.3e-6)
    assert res.steps == 334


def test_a_divergent_run_is_diagnosed_as_the_cli_does():
    form = fxflex.build("lebb")
    res = fxflex.run(form, 1e-3, integrator="cd", dt=2e-5)      # w_max dt far beyond 2
    ref = simulate(form, "cd", 2e-5, 1e-3, sample_every=50)
    assert res.diverged["time_s"] == ref.diverged["time_s"]
    cause = diagnose(form, "cd", 2e-5, ref)
    assert res.diverged == {**ref.diverged, **cause} and res.diverged["cause"] == "numerical"
    assert fxflex.run(form, 1e-3, integrator="cd", dt=2e-5, diagnose=False).diverged \
        == ref.diverged


def test_bad_input_raises_the_one_line_errors():
    with pytest.raises(fxflex.FxflexError, match="'beam' is not a method"):
        fxflex.build("beam")
    with pytest.raises(fxflex.FxflexError, match="--mass: not an option of lebb"):
        fxflex.build("lebb", mass="lumped")
    with pytest.raises(fxflex.FxflexError, match="build: unknown option"):
        fxflex.build("lebb", masses="lumped")
    with pytest.raises(fxflex.SceneError, match=r"^material\.nu: "):
        fxflex.scene_from_dict({"material": {"nu": 0.5}})
    with pytest.raises(fxflex.SceneError, match=r"^mesh\.solid: "):
        fxflex.load_scene(overrides=["mesh.solid=[20,3,2]"])
    with pytest.raises(fxflex.FxflexError, match="n: must be >= 1"):
        fxflex.modes(fxflex.build("lebb"), 0)
    with pytest.raises(fxflex.FxflexError, match="not a method"):
        fxflex.compare(methods=["lebb", "beam"])


def test_campbell_is_the_modes_at_each_speed():
    data = fxflex.campbell("nebb", [1000.0, 5000.0], n=3)
    assert isinstance(data, fxflex.CampbellData) and list(data.rpm) == [1000.0, 5000.0]
    for rpm, m in zip(data.rpm, data.modes):
        ref = fxflex.modes(fxflex.build("nebb", Scene().replace(**{"rotation.rpm": rpm})), 3)
        assert m.rpm == rpm and np.array_equal(m.eigenvalues, ref.eigenvalues)
    assert fxflex.campbell("lebb", [1000.0, 10000.0], n=1).unstable_ranges() == [
        (5500.0, 10000.0)]
    with pytest.raises(fxflex.FxflexError, match="speeds: expected"):
        fxflex.campbell("lebb", [])


def test_solid_methods_through_the_api(distributed_rtol):
    """FFRF and TLF on a 10 x 2 x 2 mesh (distributed under mpirun: COMM_WORLD by default)."""
    scene = load_scene(overrides=SOLID)
    for method in ("ffrf", "tlf"):
        form = fxflex.build(method, scene, need_steady=True)
        ref = build(method, scene, MPI.COMM_WORLD)
        if method == "tlf":                 # distributed over the default communicator
            assert form.comm.size == MPI.COMM_WORLD.size
        st = ref.steady_state()             # bit for bit but for a distributed direct solve
        np.testing.assert_allclose(fxflex.steady(form).tip, st.tip, atol=0.0,
                                   rtol=distributed_rtol(ref, st) if ref.distributed else 0.0)
        assert fxflex.stability(form)[0] is True
        res, ref_res = fxflex.run(form, 2e-5), simulate(ref, *default_integration(
            method, None, None), 2e-5, sample_every=10**6)
        assert np.array_equal(res.tip, ref_res.tip), method
    assert fxflex.modes(form, 2).stable is True


def test_compare_is_the_cli_s_study():
    scene = load_scene(overrides=SOLID)
    res = fxflex.compare(scene, ["lebb"], paper_window=2e-4)
    assert res["methods"] == ["lebb"] and "report" in res and res["steady"]
    for row in res["steady"]:
        at = scene.replace(**{"rotation.rpm": row["rpm"], "damping.c": row["c"]})
        tip = build("lebb", at, MPI.COMM_WORLD).steady_state().tip
        assert row["tip_mm"] == [float(x) for x in 1e3 * tip]


@pytest.mark.serial
def test_the_csv_is_the_cli_s_byte_for_byte(tmp_path):
    form = fxflex.build("lebb")
    mine = tmp_path / "api.csv"
    res = fxflex.run(form, 1e-3, out=mine, history=True)
    cli = tmp_path / "cli.csv"
    p = subprocess.run([sys.executable, "-m", "fxflex", "run", "--method", "lebb", "--t-end",
                        "1e-3", "--out", str(cli), "--json"], capture_output=True, text=True,
                       timeout=300)
    assert p.returncode == 0, p.stderr
    assert mine.read_bytes() == cli.read_bytes()
    out = json.loads(p.stdout)
    assert [out["tip_mm"][k] for k in ("longitudinal", "orthogonal", "load")] \
        == list(1e3 * res.tip)
    meta, columns, data = read_series(mine)
    assert columns[:4] == list(api.SERIES_COLUMNS) and meta["method"] == "lebb"
    np.testing.assert_allclose(data, np.array(res.history), rtol=1e-11, atol=0)  # 12 digits
    with pytest.raises(fxflex.FxflexError, match="out: "):
        fxflex.run(form, 1e-4, out=tmp_path)                    # a folder, refused up front


@pytest.mark.serial
def test_quickstart_demo_runs_to_its_checked_value():
    source = DEMO.read_text()
    assert "from fxflex" not in source and "import fxflex." not in source
    p = subprocess.run([sys.executable, str(DEMO)], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert "checked: lowest LEBB frequency" in p.stdout.splitlines()[-1]
