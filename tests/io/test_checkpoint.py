"""Checkpoints and --resume: a run killed with SIGKILL continues where it stopped, its CSV ends
byte for byte as an uninterrupted run's, and a checkpoint refuses a run it does not belong to."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from fxflex.bench.common import child_env
from fxflex.io.series import read_series

# spawns (and kills) fxflex runs, some under their own mpirun: a child of an mpirun'd process would
# inherit its MPI environment
pytestmark = pytest.mark.serial

FXFLEX = [sys.executable, "-m", "fxflex"]


def fxflex(*args, ranks=1):
    cmd = [*FXFLEX, *args]
    if ranks > 1:
        cmd = ["mpirun", "-n", str(ranks)] + cmd
    return cmd


def run_json(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True, env=child_env())
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def kill_after_first_checkpoint(cmd, ckpt, timeout=120.0):
    """Start ``cmd`` in its own process group, SIGKILL the group as soon as the checkpoint file
    exists; return the checkpoint's meta. Fails if the run ended before it was killed."""
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=child_env(), start_new_session=True)
    t0 = time.monotonic()
    try:
        while not os.path.exists(ckpt):
            assert proc.poll() is None, "the run ended before its first checkpoint"
            assert time.monotonic() - t0 < timeout
            time.sleep(0.01)
        time.sleep(0.1)                       # let it write rows past the checkpoint
    finally:
        os.killpg(proc.pid, signal.SIGKILL)   # the run and, under mpirun, its ranks
        proc.wait()
    assert proc.returncode == -signal.SIGKILL, "the run finished before it was killed"
    with np.load(ckpt) as data:
        return json.loads(str(data["meta"]))


def check_resumed(tmp_path, args, ranks=1, resume_ranks=None):
    ref, cut = tmp_path / "ref.csv", tmp_path / "cut.csv"
    ckpt = tmp_path / "cut.ckpt"
    whole = run_json(fxflex(*args, "--out", str(ref), "--json", ranks=ranks))
    meta = kill_after_first_checkpoint(
        fxflex(*args, "--out", str(cut), "--checkpoint", str(ckpt), ranks=ranks), str(ckpt))
    assert 0 < meta["step"] < whole["steps"]
    assert os.path.getsize(cut) >= meta["series"]["bytes"]
    resumed = run_json(fxflex(*args, "--resume", str(ckpt), "--json",
                              ranks=resume_ranks or ranks))
    assert resumed["resumed_from_step"] >= meta["step"] and resumed["diverged"] is None
    assert resumed["steps"] == whole["steps"]
    return whole, resumed, ref, cut


@pytest.mark.serial
def test_killed_beam_run_resumes_bit_for_bit(tmp_path):
    args = ["run", "--method", "lebb", "--t-end", "0.02", "--checkpoint-every", "2500"]
    whole, resumed, ref, cut = check_resumed(tmp_path, args)
    # --checkpoint-every is not part of the reference run: its header carries no checkpoint
    assert ref.read_bytes() == cut.read_bytes()
    assert resumed["tip_mm"] == whole["tip_mm"]
    data = read_series(cut)[2]
    assert np.all(np.diff(data[:, 0]) > 0) and len(data) == 25001   # every 2 steps of 0.4 us


@pytest.mark.serial
def test_killed_tlf_run_on_two_ranks_resumes_bit_for_bit(tmp_path):
    """Checkpoint gathered on rank 0 in canonical node order; same rank count: identical."""
    args = ["run", "--method", "tlf", "--set", "mesh.solid=[10,2,2]", "--t-end", "0.012",
            "--dt", "2e-6", "--checkpoint-every", "1000"]
    whole, resumed, ref, cut = check_resumed(tmp_path, args, ranks=2)
    assert ref.read_bytes() == cut.read_bytes()
    assert resumed["tip_mm"] == whole["tip_mm"]


@pytest.mark.serial
def test_two_rank_checkpoint_resumes_on_one_rank(tmp_path):
    """Another partition assembles in another order: the same run to round-off."""
    args = ["run", "--method", "tlf", "--set", "mesh.solid=[10,2,2]", "--t-end", "0.002",
            "--dt", "2e-6"]
    ckpt = tmp_path / "a.ckpt"
    whole = run_json(fxflex(*args, "--out", str(tmp_path / "a.csv"), "--checkpoint", str(ckpt),
                            "--checkpoint-every", "500", "--json", ranks=2))
    resumed = run_json(fxflex(*args, "--resume", str(ckpt), "--json"))
    assert resumed["resumed_from_step"] == 500
    a, b = (np.array(list(d["tip_mm"].values())) for d in (whole, resumed))
    # the same run on 2 ranks then 1: distributed sums round differently, amplified over the steps
    assert np.abs(a - b).max() <= 1e-9 * np.abs(a).max()


@pytest.mark.parametrize("change, words", [
    (["--rpm", "2000"], "rotation.rpm was 1000.0, now 2000.0"),
    (["--set", "geometry.twist_deg=0"], "geometry.twist_deg"),
    (["--integrator", "cd", "--dt", "4e-7"], "--integrator \"ab2\""),
    (["--dt", "2e-7"], "--dt (s) 4e-07"),
    (["--t-end", "0.004"], "--t-end (s) 0.002"),
])
def test_a_checkpoint_refuses_another_run(tmp_path, change, words):
    args = ["run", "--method", "lebb", "--t-end", "0.002"]
    csv, ckpt = tmp_path / "a.csv", tmp_path / "a.ckpt"
    run_json(fxflex(*args, "--out", str(csv), "--checkpoint", str(ckpt), "--checkpoint-every",
                    "1000", "--json"))
    before = (csv.read_bytes(), ckpt.read_bytes())
    r = subprocess.run(fxflex(*[a for a in args if a not in ("--t-end", "0.002")]
                              + (["--t-end", "0.002"] if "--t-end" not in change else []),
                              *change, "--resume", str(ckpt)),
                       capture_output=True, text=True, env=child_env())
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2 and len(lines) == 1 and words in lines[0], r.stderr
    assert lines[0].startswith("fxflex: error: --resume:") and r.stdout == ""
    assert (csv.read_bytes(), ckpt.read_bytes()) == before        # nothing touched


def test_resume_refuses_another_method_and_a_foreign_series(tmp_path):
    csv, ckpt = tmp_path / "a.csv", tmp_path / "a.ckpt"
    run_json(fxflex("run", "--method", "lebb", "--t-end", "0.001", "--out", str(csv),
                    "--checkpoint", str(ckpt), "--checkpoint-every", "1000", "--json"))
    r = subprocess.run(fxflex("run", "--method", "nebb", "--t-end", "0.001", "--resume",
                              str(ckpt)), capture_output=True, text=True, env=child_env())
    assert r.returncode == 2 and "--method \"lebb\"" in r.stderr and len(
        r.stderr.strip().splitlines()) == 1
    other = tmp_path / "b.csv"
    other.write_text("# {}\nt_s\n")
    r = subprocess.run(fxflex("run", "--method", "lebb", "--t-end", "0.001", "--resume",
                              str(ckpt), "--out", str(other)),
                       capture_output=True, text=True, env=child_env())
    assert r.returncode == 2 and "does not begin with" in r.stderr
    assert other.read_text() == "# {}\nt_s\n"
    r = subprocess.run(fxflex("run", "--method", "lebb", "--resume", str(csv)),
                       capture_output=True, text=True, env=child_env())
    assert r.returncode == 2 and "not a readable fxflex checkpoint" in r.stderr


def test_generalized_alpha_resumes_to_the_newton_tolerance(tmp_path):
    """The modified Newton's factor is not checkpointed (its renewals follow measured timings):
    a resumed NEBB run agrees with an uninterrupted one to the Newton tolerance, row for row."""
    args = ["run", "--method", "nebb", "--integrator", "generalized-alpha", "--t-end", "0.02"]
    ref, cut, ckpt = tmp_path / "ref.csv", tmp_path / "cut.csv", tmp_path / "cut.ckpt"
    whole = run_json(fxflex(*args, "--out", str(ref), "--json"))
    run_json(fxflex(*args, "--out", str(cut), "--checkpoint", str(ckpt), "--checkpoint-every",
                    "300", "--json"))
    with np.load(ckpt) as data:
        meta = json.loads(str(data["meta"]))
        assert sorted(data.files) == ["meta", "q", "scheme/a", "scheme/qdd", "v"]
    assert meta["step"] == 900 and meta["settings"]["rho_inf"] == 0.9
    resumed = run_json(fxflex(*args, "--resume", str(ckpt), "--json"))
    assert resumed["resumed_from_step"] == 900 and resumed["steps"] == whole["steps"]
    a, b = read_series(ref)[2], read_series(cut)[2]
    assert a.shape == b.shape and np.array_equal(a[:, 0], b[:, 0])
    assert np.abs(a[:, 1:4] - b[:, 1:4]).max() < 1e-4 * np.abs(a[:, 1:4]).max()
