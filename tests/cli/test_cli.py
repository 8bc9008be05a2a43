"""The command line contract (SPEC section 8): JSON envelope, one-line errors, exit status."""

import json
import os
import subprocess
import sys

import pytest

from fxflex.cli import main

# the CLI in-process and as a child: only rank 0 prints, so the output checks are one-rank checks,
# and a child of an mpirun'd process would inherit its MPI environment
pytestmark = pytest.mark.serial

FXFLEX = [sys.executable, "-m", "fxflex"]


def run(*args, cwd=None):
    return subprocess.run([*FXFLEX, *args], capture_output=True, text=True, cwd=cwd)


@pytest.mark.parametrize("args, words", [
    (["steady", "--method", "ffrx"], "allowed: ffrf gcms tlf lebb nebb ancf"),
    (["steady"], "--method"),
    (["info", "--set", "geometry.lenght=2"], "geometry.lenght"),
    (["info", "--scene", "/nonexistent.toml"], "file not found"),
    (["info", "--set", "mesh.solid=[10,3,2]"], "even"),
    (["steady", "--method", "tlf", "--rpm", "-5"], "rotation.rpm"),
    (["steady", "--method", "tlf", "--rpm", "fast"], "--rpm"),
    (["run", "--method", "tlf", "--dt", "0"], "--dt"),
    (["run", "--method", "lebb", "--force-eval", "ufl"], "--force-eval"),
    (["run", "--method", "tlf", "--force-eval", "element"], "--force-eval"),
    (["run", "--method", "nebb", "--mass", "lumped"], "--mass"),
    (["run", "--method", "tlf", "--out", "/nonexistent/dir/x.csv"], "--out"),
    (["bench", "nosuch"], "nosuch"),
    (["bench", "steady", "--reference"], "--reference"),
    # physically meaningless scenes and degenerate meshes (issue 7)
    (["run", "--method", "lebb", "--rpm", "1e300"], "rotation.rpm"),
    (["run", "--method", "lebb", "--rpm", "70000"], "allowed: below 6.985e+04 rpm"),
    (["steady", "--method", "lebb", "--set", "material.E=1e-3"], "rotation.rpm"),
    (["run", "--method", "lebb", "--set", "load.line_load=-1e12"], "load.line_load"),
    (["run", "--method", "nebb", "--set", "material.rho=1e-300"], "speed of light"),
    (["run", "--method", "tlf", "--set", "geometry.root_z=1e-9"], "degenerate section"),
    (["run", "--method", "tlf", "--set", "mesh.solid=[1,2,2]", "--set",
      "geometry.twist_deg=180"], "at least 2 divisions along X"),
    (["run", "--method", "ancf", "--set", "mesh.beam_elements=1", "--set",
      "geometry.twist_deg=-100"], "at least 2 ANCF elements"),
    (["run", "--method", "ffrf", "--set", "mesh.solid=[2,2,2]", "--set",
      "reduction.ffrf_modes=100"], "at most 54"),
    (["run", "--method", "lebb", "--checkpoint-every", "10"], "--checkpoint-every"),
    (["run", "--method", "lebb", "--checkpoint-every", "0", "--out", "a.csv"],
     "--checkpoint-every"),
    (["run", "--method", "lebb", "--resume", "nosuch.ckpt"], "file not found"),
    (["run", "--method", "tlf", "--resume", "x.ckpt", "--fields", "u.xdmf"], "--fields"),
    (["compare", "--methods", "ffrf,fem"], "fem"),
    # modes and the Campbell diagram (issue 6)
    (["modes", "--method", "lebb", "--campbell", "5000:1000:3"], "--campbell"),
    (["modes", "--method", "lebb", "--campbell", "0:1000"], "--campbell"),
    (["modes", "--method", "lebb", "--n", "0"], "--n"),
    (["modes", "--method", "lebb", "--mass", "lumped"], "--mass"),
    (["modes", "--method", "tlf", "--rpm", "-1"], "rotation.rpm"),
    (["run", "--method", "lebb", "--integrator", "generalized-alpha", "--rho-inf", "1.5"],
     "--rho-inf"),
    (["run", "--method", "ancf", "--rho-inf", "0.5"], "--rho-inf"),
    (["run", "--method", "ancf", "--integrator", "implicit"], "--integrator"),
])
def test_bad_input_is_one_line_and_exit_2(args, words, tmp_path):
    r = run(*args, cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("fxflex: error:") and words in lines[0]
    assert r.stdout == "" and list(tmp_path.iterdir()) == []   # nothing half-written


def test_info_json_envelope():
    r = run("info", "--json", "--set", "mesh.solid=[10,2,2]")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["fxflex_version"] and len(d["scene_hash"]) == 16
    assert d["scene"]["mesh"]["solid"] == [10, 2, 2]
    assert d["methods"]["tlf"]["dof"] == 3 * 10 * 3 * 3


def test_help_and_version():
    assert run("--help").returncode == 0
    r = run("--version")
    assert r.returncode == 0 and "fxflex" in r.stdout


def test_python_m_and_entry_point_agree():
    exe = os.path.join(os.path.dirname(sys.executable), "fxflex")
    if not os.path.exists(exe):
        pytest.skip("entry point not installed in this environment")
    a = subprocess.run([exe, "info", "--json"], capture_output=True, text=True)
    b = run("info", "--json")
    assert json.loads(a.stdout)["scene_hash"] == json.loads(b.stdout)["scene_hash"]


def test_generalized_alpha_run_writes_csv_and_newton_counters(tmp_path, capsys):
    """The default step at 2000 rpm (20 us (1000/2000)^1.5 = 7.07 us) shortened to end exactly
    at --t-end; rho_inf and the Newton counters in the JSON, the CSV as for explicit runs."""
    out = tmp_path / "series.csv"
    assert main(["run", "--method", "lebb", "--integrator", "generalized-alpha", "--rpm", "2000",
                 "--t-end", "1e-3", "--out", str(out), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["integrator"] == "generalized-alpha" and d["rho_inf"] == 0.9
    assert d["steps"] == 142 and d["dt_s"] == pytest.approx(1e-3 / 142)
    assert d["t_s"] == pytest.approx(1e-3) and d["diverged"] is None
    assert d["newton"]["factorizations"] == 1 and d["newton"]["steps"] == 142
    lines = out.read_text().splitlines()
    meta = json.loads(" ".join(ln[2:] for ln in lines if ln.startswith("#")))
    assert meta["rho_inf"] == 0.9 and meta["integrator"] == "generalized-alpha"
    rows = [ln.split(",") for ln in lines if not ln.startswith("#")]
    assert rows[0][:4] == ["t_s", "longitudinal_m", "orthogonal_m", "load_m"]
    assert float(rows[-1][0]) == pytest.approx(1e-3) and len(rows) == 1 + 143


def test_generalized_alpha_reports_a_physical_divergence(capsys):
    assert main(["run", "--method", "lebb", "--integrator", "generalized-alpha", "--rho-inf",
                 "0.5", "--rpm", "10000", "--t-end", "0.01", "--json",
                 "--set", "mesh.beam_elements=4"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["diverged"] is not None and d["diverged"]["cause"] == "physical"
    assert d["rho_inf"] == 0.5 and d["t_s"] < 0.01


def test_a_bench_that_refuses_leaves_no_folder(tmp_path, monkeypatch, capsys):
    """bench pybmodes without pyBModes: one line, exit 2, and the --out folders it had made
    (two levels, both new) are gone again."""
    monkeypatch.setitem(sys.modules, "pybmodes", None)          # import pybmodes fails
    monkeypatch.setitem(sys.modules, "pybmodes.models", None)
    assert main(["bench", "pybmodes", "--out", str(tmp_path / "a" / "b")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "needs pyBModes" in err[0], err
    assert list(tmp_path.iterdir()) == []
