"""The memory check before a build (issue 11): what the machine has, what a build needs, and the
one-line refusal of a build that does not fit."""

import os
import re
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from fxflex import memory
from fxflex.errors import FxflexError
from fxflex.scene import Scene

FXFLEX = [sys.executable, "-m", "fxflex"]
GB = 1 << 30

#: measured peak resident memory (MB) of `fxflex steady` (docs/robustness.md, "Memory and size";
#: ANCF: of `fxflex run --t-end 2e-6`, the larger since its steady state builds no system
#: matrices): the estimate must lie at or above each, and not far above
MEASURED = {
    ("lebb", 10): 64, ("lebb", 100): 126, ("lebb", 200): 300, ("lebb", 400): 902,
    ("nebb", 100): 132, ("nebb", 200): 310,
    ("ancf", 10): 137, ("ancf", 50): 556, ("ancf", 100): 1711,
    ("tlf", (20, 4, 2)): 173, ("tlf", (50, 6, 4)): 200, ("tlf", (100, 12, 6)): 382,
    ("tlf", (128, 16, 8)): 808, ("tlf", (192, 24, 12)): 2899,
    ("ffrf", (20, 4, 2)): 173, ("ffrf", (50, 6, 4)): 194, ("ffrf", (100, 12, 6)): 334,
    ("ffrf", (128, 16, 8)): 632, ("ffrf", (192, 24, 12)): 2012,
    ("gcms", (20, 4, 2)): 174, ("gcms", (50, 6, 4)): 195, ("gcms", (100, 12, 6)): 334,
    ("gcms", (128, 16, 8)): 632,
}
#: ... and of `fxflex run` of TLF with the options that cost memory
MEASURED_RUN = {
    ((50, 6, 4), "invariant", None): 271, ((100, 12, 6), "invariant", None): 602,
    ((128, 16, 8), "invariant", None): 1335, ((100, 12, 6), None, None): 389,
    ((100, 12, 6), None, "consistent"): 453,
}


def fake_machine(tmp_path: Path, meminfo_kb: int, cgroup_line: str, files: dict) -> tuple:
    proc, cg = tmp_path / "proc", tmp_path / "cgroup"
    (proc / "self").mkdir(parents=True)
    (proc / "meminfo").write_text(f"MemTotal: 99999999 kB\nMemAvailable: {meminfo_kb} kB\n")
    (proc / "self" / "cgroup").write_text(cgroup_line + "\n")
    for rel, text in files.items():
        (cg / rel).parent.mkdir(parents=True, exist_ok=True)
        (cg / rel).write_text(text)
    return proc, cg


@pytest.fixture(autouse=True)
def no_env(monkeypatch):
    monkeypatch.delenv("FXFLEX_MEMORY_LIMIT", raising=False)
    monkeypatch.delenv("FXFLEX_MEMORY_CHECK", raising=False)


def test_available_is_meminfo_without_a_cgroup_limit(tmp_path):
    proc, cg = fake_machine(tmp_path, 8 * 1024 * 1024, "0::/job",
                            {"job/memory.max": "max\n", "job/memory.current": "123\n"})
    assert memory.available(proc, cg) == 8 * GB


def test_available_is_the_room_under_the_tightest_cgroup_v2_limit(tmp_path):
    # the parent's limit (3 GB, 1 GB used, 0.5 GB reclaimable cache) binds, not the job's (6 GB)
    proc, cg = fake_machine(tmp_path, 8 * 1024 * 1024, "0::/user/job", {
        "user/memory.max": f"{3 * GB}\n", "user/memory.current": f"{GB}\n",
        "user/memory.stat": f"anon 1\ninactive_file {GB // 2}\n",
        "user/job/memory.max": f"{6 * GB}\n", "user/job/memory.current": f"{GB}\n"})
    assert memory.available(proc, cg) == 2 * GB + GB // 2


def test_available_reads_cgroup_v1(tmp_path):
    proc, cg = fake_machine(tmp_path, 8 * 1024 * 1024, "4:memory:/box", {
        "memory/box/memory.limit_in_bytes": f"{4 * GB}\n",
        "memory/box/memory.usage_in_bytes": f"{3 * GB}\n",
        "memory/box/memory.stat": "total_inactive_file 0\n",
        "memory/memory.limit_in_bytes": "9223372036854771712\n",
        "memory/memory.usage_in_bytes": "5\n"})
    assert memory.available(proc, cg) == GB


def test_memory_limit_caps_what_is_available(tmp_path, monkeypatch):
    proc, cg = fake_machine(tmp_path, 8 * 1024 * 1024, "0::/", {})
    monkeypatch.setenv("FXFLEX_MEMORY_LIMIT", "1.5G")
    assert memory.available(proc, cg) == int(1.5 * GB)
    monkeypatch.setenv("FXFLEX_MEMORY_LIMIT", "lots")
    with pytest.raises(FxflexError, match=r"^FXFLEX_MEMORY_LIMIT: 'lots' is not a size; allowed"):
        memory.available(proc, cg)


@pytest.mark.parametrize("case", sorted(MEASURED, key=str))
def test_estimate_lies_just_above_the_measured_peak(case):
    method, size = case
    key = "mesh.beam_elements" if method in memory.BEAMS else "mesh.solid"
    est = memory.estimate(method, Scene().replace(**{key: size})).total / 1e6
    assert MEASURED[case] <= est <= 1.5 * MEASURED[case], (case, est)


@pytest.mark.parametrize("case", sorted(MEASURED_RUN, key=str))
def test_tlf_options_are_estimated(case):
    from fxflex.formulation import BuildOptions

    size, force_eval, mass = case
    est = memory.estimate("tlf", Scene().replace(**{"mesh.solid": size}), 1,
                          BuildOptions(force_eval=force_eval, mass=mass)).total / 1e6
    assert MEASURED_RUN[case] <= est <= 1.5 * MEASURED_RUN[case], (case, est)


def test_ranks_of_a_distributed_build_are_estimated():
    """TLF 128 x 16 x 8 on 2 ranks: each rank's peak was at most 558 MB (measured)."""
    big = Scene().replace(**{"mesh.solid": (128, 16, 8)})
    est = memory.estimate("tlf", big, 2).total / 1e6
    assert 2 * 558 <= est <= 1.5 * 2 * 558, est


def _peak_mb(args, env) -> float:
    """Peak resident memory (MB) of ``fxflex`` with ``args``, run in a child of a fresh process
    (RUSAGE_CHILDREN then sees that run only)."""
    code = ("import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True, "
            "stdout=subprocess.DEVNULL); "
            "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)")
    out = subprocess.run([sys.executable, "-c", code, *FXFLEX, *args], env=env,
                         capture_output=True, text=True, timeout=600, check=True)
    return int(out.stdout) / 1024.0


@pytest.mark.serial
@pytest.mark.parametrize("method, key, value, size, command", [
    ("ancf", "mesh.beam_elements", "40", 40, ["run", "--t-end", "2e-6"]),
    ("tlf", "mesh.solid", "[50,6,4]", (50, 6, 4), ["steady"])])
def test_estimate_bounds_a_real_build(method, key, value, size, command, tmp_path):
    """The estimate bounds the peak of the build's most demanding command within 1.5x: a steady
    state with its stability verdict, or for ANCF a run (the invariant route's system matrices
    are built for the time loop only: 40 elements, 409 MB against 294 MB for ``steady``)."""
    env = {**os.environ, "FXFLEX_NO_CACHE": "1", "OMP_NUM_THREADS": "1"}
    peak = _peak_mb([*command, "--method", method, "--set", f"{key}={value}", "--json"], env)
    est = memory.estimate(method, Scene().replace(**{key: size})).total / 1e6
    assert peak <= est <= 1.5 * peak, (peak, est)


def test_default_scenes_and_the_reference_meshes_are_modest():
    """Every default scene fits in 1 GB, the largest meshes fxflex itself builds through
    ``build`` (bench accuracy: 192 x 24 x 12 for FFRF, GCMS and TLF) in 8 GB."""
    for method in memory.BEAMS + memory.SOLIDS:
        assert memory.estimate(method, Scene()).total < 1e9, method
    for method in memory.SOLIDS:
        big = Scene().replace(**{"mesh.solid": (192, 24, 12)})
        assert memory.estimate(method, big).total < 8e9, method


def _cli(args, tmp_path, **env):
    full = {**os.environ, "FXFLEX_CACHE": str(tmp_path / "cache"), "OMP_NUM_THREADS": "1", **env}
    full.pop("FXFLEX_NO_CACHE", None)
    return subprocess.run([*FXFLEX, *args], env=full, capture_output=True, text=True, timeout=300)


@pytest.mark.serial
def test_a_beam_too_large_is_refused_at_once_with_one_line(tmp_path):
    res = _cli(["steady", "--method", "lebb", "--set", "mesh.beam_elements=100000000", "--json"],
               tmp_path)
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr.count("\n") == 1, res.stderr
    assert re.match(r"fxflex: error: mesh\.beam_elements = 100000000: the lebb build needs about "
                    r"[0-9.e+]+ [TGM]B \(dense matrices [^)]*\); [0-9.]+ [TGM]B available; "
                    r"allowed: up to about \d+ elements on this machine", res.stderr), res.stderr


@pytest.mark.serial
def test_a_solid_mesh_too_large_is_refused_and_leaves_no_mesh(tmp_path):
    res = _cli(["steady", "--method", "tlf", "--set", "mesh.solid=[1000,100,100]"], tmp_path)
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    # neither route fits: the refusal names the iterative one, the last "auto" tried
    assert res.stderr.startswith("fxflex: error: mesh.solid = [1000, 100, 100]: the tlf build "
                                 "(linear solver iterative) needs about "), res.stderr
    assert "allowed: meshes up to about" in res.stderr
    assert not any(p.is_file() for p in (tmp_path / "cache").rglob("*"))


@pytest.mark.serial
def test_the_limit_and_the_override(tmp_path):
    args = ["steady", "--method", "nebb", "--set", "mesh.beam_elements=40", "--json"]
    refused = _cli(args, tmp_path, FXFLEX_MEMORY_LIMIT="20000000")
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1, refused.stderr
    assert "; 20 MB available; allowed: nothing" in refused.stderr
    forced = _cli(args, tmp_path, FXFLEX_MEMORY_LIMIT="20000000", FXFLEX_MEMORY_CHECK="0")
    assert forced.returncode == 0, forced.stderr


def test_the_allowed_size_fits_and_the_next_does_not(monkeypatch):
    from mpi4py import MPI

    room = 2.0e9
    monkeypatch.setenv("FXFLEX_MEMORY_LIMIT", str(int(room)))
    scene = Scene().replace(**{"mesh.beam_elements": 10_000})
    with pytest.raises(FxflexError) as info:
        memory.check("ancf", scene, MPI.COMM_SELF)
    n = int(re.search(r"allowed: up to about (\d+) elements", str(info.value)).group(1))
    fits = lambda k: memory.estimate("ancf", scene.replace(**{"mesh.beam_elements": k})).total
    assert fits(n) <= room < fits(int(1.02 * n) + 1)


def test_the_python_api_is_checked_too(monkeypatch):
    from mpi4py import MPI

    from fxflex.formulation import build

    huge = Scene().replace(**{"mesh.beam_elements": 10 ** 8})
    with pytest.raises(FxflexError, match=r"^mesh\.beam_elements = 100000000: the nebb build"):
        build("nebb", huge, MPI.COMM_SELF)


@pytest.mark.mpi
def test_ranks_on_one_machine_are_added_up(monkeypatch):
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    scene = Scene().replace(**{"mesh.beam_elements": 300})
    one = memory.estimate("lebb", scene, 1).total
    assert memory.estimate("lebb", scene, comm.size).total == pytest.approx(comm.size * one)
    monkeypatch.setenv("FXFLEX_MEMORY_LIMIT", str(int(1.5 * one)))    # one rank's worth fits
    assert memory.check("lebb", scene, MPI.COMM_SELF) is not None
    with pytest.raises(FxflexError, match=rf"\({comm.size} ranks on one machine\)"):
        memory.check("lebb", scene, comm)
