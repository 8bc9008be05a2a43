"""``fxflex modes`` and ``fxflex steady``'s stability verdict through the command line (SPEC
section 8): the JSON contract, the Campbell files (its one-line errors: tests/cli/test_cli.py)."""

import json
import subprocess
import sys

import pytest

# spawns the fxflex CLI: a child of an mpirun'd process would inherit its MPI environment
pytestmark = pytest.mark.serial

FXFLEX = [sys.executable, "-m", "fxflex"]
LABELS = {"axial", "in-plane", "out-of-plane", "torsion"}


def run(*args, cwd=None):
    return subprocess.run([*FXFLEX, *args], capture_output=True, text=True, cwd=cwd)


def test_modes_json_contract():
    r = run("modes", "--method", "lebb", "--rpm", "10000", "--n", "6", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["fxflex_version"] and d["scene_hash"] and d["scene"]["rotation"]["rpm"] == 10000.0
    assert d["method"] == "lebb" and d["rpm"] == 10000.0 and d["dof"] == 60 and d["n"] == 6
    f, g, lab = d["frequencies_hz"], d["growth_rates"], d["labels"]
    assert len(f) == len(g) == len(lab) == 6
    assert f == sorted(f) and set(lab) <= LABELS
    # the divergence: a pair of real roots +-a first (0 Hz), the growing one ahead
    assert f[0] == f[1] == 0.0 and g[0] > 700 and g[1] < -700 and d["stable"] is False
    assert all(x > 0 for x in f[2:]) and all(x < 0 for x in g[2:])
    text = run("modes", "--method", "lebb", "--rpm", "10000", "--n", "6")
    assert text.returncode == 0 and "stable: False" in text.stdout and "in-plane" in text.stdout


def test_campbell_files(tmp_path):
    out = tmp_path / "c"
    r = run("modes", "--method", "lebb", "--campbell", "0:10000:5", "--n", "4", "--out",
            str(out), "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    c = d["campbell"]
    assert c["rpm"] == [0.0, 2500.0, 5000.0, 7500.0, 10000.0]
    assert c["stable"] == [True, True, True, False, False]
    assert c["unstable_rpm"] == [[6250.0, 10000.0]]
    assert all(len(row) == 4 for row in c["frequencies_hz"])
    assert (out / "campbell_lebb.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rows = (out / "campbell_lebb.csv").read_text().splitlines()
    assert rows[0] == "rpm,mode,frequency_hz,growth_rate_1_s,label,stable" and len(rows) == 21
    saved = json.loads((out / "campbell_lebb.json").read_text())
    assert saved["campbell"] == c and saved["files"]["png"].endswith("campbell_lebb.png")
    assert r.stderr.count("rpm (") == 5          # one progress line per speed


@pytest.mark.parametrize("method", ["tlf", "gcms"])
def test_steady_fills_stable(method):
    r = run("steady", "--method", method, "--rpm", "10000", "--set", "mesh.solid=[10,2,2]",
            "--set", "reduction.gcms_modes=30", "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["stable"] is (method == "tlf")
