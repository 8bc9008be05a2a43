"""Output paths that would destroy data or cannot be written are refused before anything is
written; a write that fails during a run leaves no half-written series; --t-end is honoured
whatever the step; SIGINT with --json reports what was done (issue 11, items 4, 5 and 7)."""

import json
import os
import resource
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from fxflex.bench.common import child_env
from fxflex.io.series import read_series

FXFLEX = [sys.executable, "-m", "fxflex"]
LEBB = ["run", "--method", "lebb", "--t-end", "1e-4"]
SCENE = "[rotation]\nrpm = 1000.0\n"


def run(*args, cwd, env=None, **kwargs):
    return subprocess.run([*FXFLEX, *args], capture_output=True, text=True, cwd=cwd,
                          env={**child_env(), **(env or {})}, **kwargs)


def error_line(r) -> str:
    """The one stderr line of a failed command (asserts there is exactly one)."""
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("fxflex: error: "), r.stderr
    assert "Traceback" not in r.stderr and r.stdout == ""
    return lines[0]


def snapshot(folder) -> dict:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.mark.serial
@pytest.mark.parametrize("args, words", [
    (LEBB + ["--out", "x.csv", "--checkpoint", "x.csv"], ["--out and --checkpoint", "x.csv"]),
    (LEBB + ["--scene", "s.toml", "--out", "s.toml"], ["--out", "s.toml", "--scene"]),
    (LEBB + ["--scene", "s.toml", "--checkpoint", "./s.toml"], ["--checkpoint", "--scene"]),
    (LEBB + ["--scene", "s.toml", "--out", "link.csv"], ["--out", "link.csv", "--scene"]),
    (["run", "--method", "tlf", "--out", "x.xdmf", "--fields", "x.xdmf"],
     ["--out and --fields", "x.xdmf"]),
    (["run", "--method", "tlf", "--out", "x.h5", "--fields", "x.xdmf"], ["--fields", "x.h5"]),
    (LEBB + ["--out", ""], ["--out", "empty"]),
    (LEBB + ["--checkpoint", ""], ["--checkpoint", "empty"]),
    (["run", "--method", "tlf", "--fields", "x.vtk"], ["--fields", "x.vtk", ".xdmf"]),
    (LEBB + ["--out", "/proc/a.csv"], ["--out", "/proc"]),
    (LEBB + ["--out", "sub"], ["--out", "sub", "is a directory"]),
    (LEBB + ["--out", "/dev/full"], ["--out", "/dev/full", "not a regular file"]),
    # a checkpoint is renamed over its file: a wrong verdict must not replace a system device
    (LEBB + ["--checkpoint", "pipe"], ["--checkpoint", "pipe", "not a regular file"]),
    (LEBB + ["--out", "s.toml/a.csv"], ["--out", "not a directory"]),
    (["modes", "--method", "lebb", "--out", "s.toml"], ["--out", "s.toml", "not a directory"]),
    (["modes", "--method", "lebb", "--out", "/proc/m"], ["--out", "/proc"]),
    (["modes", "--method", "lebb", "--out", ""], ["--out", "empty"]),
    (["compare", "--out", "/dev/full"], ["--out", "/dev/full", "not a directory"]),
    (["compare", "--out", "/proc/c"], ["--out", "/proc"]),
    (["bench", "steady", "--out", "s.toml"], ["--out", "s.toml", "not a directory"]),
    (["bench", "steady", "--out", "/proc/b"], ["--out", "/proc"]),
])
def test_an_output_that_cannot_be_written_or_destroys_data_is_refused(args, words, tmp_path):
    (tmp_path / "s.toml").write_text(SCENE)
    (tmp_path / "link.csv").symlink_to("s.toml")
    (tmp_path / "sub").mkdir()
    os.mkfifo(tmp_path / "pipe")
    before = snapshot(tmp_path)
    r = run(*args, cwd=tmp_path, timeout=300)
    assert r.returncode == 2, r.stderr
    line = error_line(r)
    assert all(w in line for w in words), line
    assert snapshot(tmp_path) == before and sorted(p.name for p in tmp_path.iterdir()) == [
        "link.csv", "pipe", "s.toml", "sub"]
    assert (tmp_path / "pipe").is_fifo()
    assert list((tmp_path / "sub").iterdir()) == []


@pytest.mark.serial
def test_an_immutable_folder_is_refused_before_the_build(locked, tmp_path):
    r = run(*LEBB, "--out", str(locked / "a.csv"), cwd=tmp_path, timeout=300)
    assert r.returncode == 2
    assert f"--out: cannot write into {locked}" in error_line(r)
    assert list(locked.iterdir()) == []


#: the MPI singleton's PMIx keeps its store in files bigger than the limit: keep it in memory
IN_MEMORY = {"PMIX_MCA_gds": "hash"}


def _file_size_limit(nbytes):
    """preexec_fn: files of this process may not grow beyond ``nbytes`` (a disk that fills)."""
    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)     # a write beyond it fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, nbytes))
    return limit


@pytest.mark.serial
def test_a_series_that_fails_mid_run_is_removed_not_left_half_written(tmp_path):
    r = run("run", "--method", "lebb", "--t-end", "1e-2", "--out", "a.csv", cwd=tmp_path,
            timeout=300, env=IN_MEMORY, preexec_fn=_file_size_limit(200_000))
    assert r.returncode == 1
    line = error_line(r)
    assert "--out: cannot write a.csv" in line and "removed" in line, line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.serial
def test_a_series_that_fails_mid_run_is_cut_back_to_its_checkpoint(tmp_path):
    r = run("run", "--method", "lebb", "--t-end", "1e-2", "--out", "a.csv", "--checkpoint",
            "a.ckpt", "--checkpoint-every", "1000", cwd=tmp_path, timeout=300, env=IN_MEMORY,
            preexec_fn=_file_size_limit(200_000))
    assert r.returncode == 1
    assert "cut back" in error_line(r)
    with np.load(tmp_path / "a.ckpt") as data:
        meta = json.loads(str(data["meta"]))
    assert os.path.getsize(tmp_path / "a.csv") == meta["series"]["bytes"] > 0
    resumed = run("run", "--method", "lebb", "--t-end", "1e-2", "--resume", "a.ckpt", "--json",
                  cwd=tmp_path, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert json.loads(resumed.stdout)["t_s"] == pytest.approx(1e-2, rel=1e-12)
    assert read_series(tmp_path / "a.csv")[2][-1, 0] == pytest.approx(1e-2, rel=1e-12)


@pytest.mark.serial
@pytest.mark.parametrize("extra, dt, steps", [
    (["--dt", "5e-4", "--integrator", "generalized-alpha"], 1e-4, 1),
    (["--dt", "1", "--integrator", "generalized-alpha"], 1e-4, 1),
    (["--dt", "3e-5"], 2.5e-5, 4),
])
def test_the_run_ends_at_t_end_when_the_step_does_not_divide_it(extra, dt, steps, tmp_path):
    r = run(*LEBB, *extra, "--out", "a.csv", "--json", cwd=tmp_path, timeout=300)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["t_s"] == pytest.approx(1e-4, rel=1e-12) and d["steps"] == steps
    assert d["dt_s"] == pytest.approx(dt, rel=1e-12)
    assert any("shortened" in w for w in d["warnings"])
    assert read_series(tmp_path / "a.csv")[2][-1, 0] == pytest.approx(1e-4, rel=1e-12)


@pytest.mark.serial
def test_a_step_that_divides_t_end_is_kept_as_given(tmp_path):
    r = run(*LEBB, "--dt", "1e-5", "--integrator", "generalized-alpha", "--json", cwd=tmp_path,
            timeout=300)
    d = json.loads(r.stdout)
    assert d["dt_s"] == 1e-5 and d["steps"] == 10 and d["warnings"] == []


@pytest.mark.serial
def test_sigint_with_json_reports_what_was_done_after_the_csv_is_flushed(tmp_path):
    csv = tmp_path / "a.csv"
    proc = subprocess.Popen([*FXFLEX, "run", "--method", "lebb", "--t-end", "10", "--out",
                             str(csv), "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=child_env())
    t0 = time.monotonic()
    while not (csv.exists() and csv.read_text().count("\n") > 60):
        assert proc.poll() is None and time.monotonic() - t0 < 120
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    d = json.loads(out)
    assert d["interrupted"] is True and d["diverged"] is None and d["series"] == str(csv)
    assert 0 < d["t_s"] < 10 and all(v is not None for v in d["tip_mm"].values())
    last = read_series(csv)[2][-1, 0]        # the last sample, at most one interval before
    t = float(f"{d['t_s']:.12g}")            # the series holds times to 12 digits (SeriesWriter)
    assert last <= t < last + 10 / 20000 + 1e-12
