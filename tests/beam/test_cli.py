"""The beam methods through the command line: steady, run, info, JSON, CSV, MPI."""

import json
import os
import shutil
import subprocess
import sys

import pytest

from fxflex.cli import main

# the CLI in-process and as a child: only rank 0 prints, so the output checks are one-rank checks,
# and a child of an mpirun'd process would inherit its MPI environment
pytestmark = pytest.mark.serial


def run_json(capsys, *argv):
    assert main([*argv, "--json"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1
    return json.loads(out[0])


@pytest.mark.parametrize("method", ["lebb", "nebb", "ancf"])
def test_steady_json(capsys, method):
    d = run_json(capsys, "steady", "--method", method, "--set", "mesh.beam_elements=4")
    assert d["method"] == method and d["converged"] and d["stable"] is True
    assert d["dof"] == {"lebb": 24, "nebb": 24, "ancf": 87}[method]
    assert set(d["tip_mm"]) == {"longitudinal", "orthogonal", "load"}
    assert d["tip_mm"]["load"] < 0 and d["scene_hash"]


@pytest.mark.parametrize("method,extra", [("lebb", []), ("nebb", ["--force-eval", "element"]),
                                          ("ancf", ["--force-eval", "element"]),
                                          ("ancf", ["--damping-model", "absolute"]),
                                          ("nebb", ["--set", "rotation.profile=spin-up",
                                                    "--set", "rotation.spinup_time=1e-3",
                                                    "--set", "geometry.hub_radius=0.3"]),
                                          ("ancf", ["--set", "rotation.profile=spin-up",
                                                    "--set", "rotation.spinup_time=1e-3",
                                                    "--set", "load.tip_force=[0,100,-50]",
                                                    "--set", "section.torsion=saint-venant"])])
def test_run_writes_csv(capsys, tmp_path, method, extra):
    out = tmp_path / "series.csv"
    d = run_json(capsys, "run", "--method", method, "--t-end", "2e-5", "--out", str(out),
                 "--set", "mesh.beam_elements=3", *extra)
    assert d["diverged"] is None and d["steps"] > 5
    lines = [ln for ln in out.read_text().splitlines() if not ln.startswith("#")]
    header = lines[0].split(",")
    assert header[:4] == ["t_s", "longitudinal_m", "orthogonal_m", "load_m"]
    assert ("drive_torque_Nm" in header) == (method != "ancf")
    assert len(lines) > 5


def test_lebb_diverges_physically_at_10000_rpm(capsys):
    d = run_json(capsys, "run", "--method", "lebb", "--rpm", "10000", "--t-end", "0.006",
                 "--sample-dt", "1e-5", "--set", "mesh.beam_elements=4")
    assert d["diverged"] is not None and d["diverged"]["cause"] == "physical"


def test_force_eval_rejected_for_lebb(capsys):
    assert main(["run", "--method", "lebb", "--force-eval", "element"]) == 2
    assert "--force-eval" in capsys.readouterr().err


def test_info_counts(capsys):
    d = run_json(capsys, "info", "--set", "mesh.ancf_root=full")
    assert d["methods"]["lebb"]["dof"] == 60 and d["methods"]["ancf"]["dof"] == 210


@pytest.mark.skipif(shutil.which("mpirun") is None, reason="no mpirun")
def test_two_ranks_print_once():
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1", OMP_NUM_THREADS="1")
    cmd = ["mpirun", "-n", "2", sys.executable, "-m", "fxflex", "run", "--method", "ancf",
           "--t-end", "1e-5", "--set", "mesh.beam_elements=3", "--json"]
    p = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)
    assert p.returncode == 0, p.stderr
    lines = p.stdout.strip().splitlines()
    assert len(lines) == 1 and json.loads(lines[0])["method"] == "ancf"
