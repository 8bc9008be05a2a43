"""Under mpirun an error on any rank ends every rank promptly with one line, printed once, and a
non-zero exit status - whether every rank meets it or one rank alone (issue 11, item 3). Each
test starts its own ``mpirun -n 2`` and is therefore serial."""

import subprocess
import sys
import textwrap

import pytest

from fxflex.bench.common import child_env

MPIRUN = ["mpirun", "-n", "2", sys.executable, "-m", "fxflex"]


def mpirun(cmd, cwd):
    return subprocess.run(cmd, capture_output=True, text=True, cwd=cwd, env=child_env(),
                          timeout=120)


def only_line(r) -> str:
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("fxflex: error: "), r.stderr
    assert r.stdout == ""
    return lines[0]


@pytest.mark.serial
def test_an_unwritable_output_folder_ends_both_ranks_with_one_line(locked, tmp_path):
    r = mpirun([*MPIRUN, "run", "--method", "tlf", "--set", "mesh.solid=[20,4,2]", "--t-end",
                "1e-3", "--out", str(locked / "a.csv")], tmp_path)
    assert r.returncode == 2
    assert f"--out: cannot write into {locked}" in only_line(r)
    assert list(locked.iterdir()) == []


@pytest.mark.serial
def test_an_output_under_proc_ends_both_ranks_with_one_line(tmp_path):
    r = mpirun([*MPIRUN, "run", "--method", "tlf", "--set", "mesh.solid=[20,4,2]", "--t-end",
                "1e-3", "--out", "/proc/a.csv"], tmp_path)
    assert r.returncode == 2 and "--out: cannot write into /proc" in only_line(r)


@pytest.mark.serial
def test_a_binary_scene_is_one_line_not_two_tracebacks(tmp_path):
    (tmp_path / "s.toml").write_bytes(bytes(range(256)) * 8)
    r = mpirun([*MPIRUN, "info", "--scene", "s.toml"], tmp_path)
    assert r.returncode != 0 and "Traceback" not in r.stderr
    only_line(r)


@pytest.mark.serial
def test_a_rank_that_fails_alone_ends_the_job_with_its_line(tmp_path):
    """Rank 1 raises while rank 0 waits in a collective for it: without the abort rank 0 would
    wait forever."""
    script = tmp_path / "alone.py"
    script.write_text(textwrap.dedent("""\
        import sys
        from fxflex import cli

        def fails_on_rank_1(args, comm):
            if comm.rank == 1:
                raise KeyError("only rank 1 sees this")
            comm.Barrier()

        cli.COMMANDS["info"] = fails_on_rank_1
        sys.exit(cli.main(["info"]))
        """))
    r = mpirun(["mpirun", "-n", "2", sys.executable, str(script)], tmp_path)
    assert r.returncode == 1
    line = only_line(r)
    assert "KeyError" in line and "only rank 1 sees this" in line
