"""The command line contract (SPEC section 8): JSON envelope, one-line errors, exit status."""

import json
import os
import subprocess
import sys

import pytest

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
    (["compare", "--methods", "ffrf,fem"], "fem"),
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
