"""Results kept and limits (issue 11, section 7): a converged equilibrium survives an eigensolver
that does not converge, ``--n`` beyond the model, ``--campbell`` speeds validated as ``--rpm`` is
(the heavy-damping verdict: test_heavy_damping.py)."""

import json
import math

import pytest

import fxflex.numerics.petsc as pep
from fxflex.cli import main

SMALL_TLF = ["--set", "mesh.solid=[10,2,2]"]          # 270 unknowns


def cli(capsys, *args):
    code = main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def pep_gives_up(monkeypatch):
    """A real SLEPc failure on a small mesh: one restart towards an unreachable residual
    (issue 11: [100000,2,2] gave 'SLEPc PEP converged 1 of 8')."""
    monkeypatch.setattr(pep, "TOL", 1e-30)
    monkeypatch.setattr(pep, "MAX_IT", 1)


@pytest.mark.serial    # checks the CLI's output, which only rank 0 prints
def test_steady_keeps_the_equilibrium_when_the_pep_does_not_converge(capsys, pep_gives_up):
    code, out, err = cli(capsys, "steady", "--method", "tlf", *SMALL_TLF, "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["converged"] is True and d["stable"] is None
    assert all(math.isfinite(v) for v in d["tip_mm"].values()) and d["tip_mm"]["load"] < 0
    assert len(d["warnings"]) == 1
    assert d["warnings"][0].startswith("stability not decided: SLEPc PEP converged ")
    assert d["warnings"][0].endswith(" of 8 eigenvalue pairs")
    assert "stability not decided" in err


@pytest.mark.serial    # checks the CLI's output, which only rank 0 prints
def test_modes_reports_the_roots_that_converged(capsys, pep_gives_up):
    code, out, err = cli(capsys, "modes", "--method", "tlf", *SMALL_TLF, "--n", "8", "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["stable"] is None and 0 < d["n"] < 8
    assert len(d["frequencies_hz"]) == len(d["growth_rates"]) == len(d["labels"]) == d["n"]
    assert f"SLEPc PEP converged {d['n']} of 8" in d["warnings"][0]


@pytest.mark.serial    # checks the CLI's output, which only rank 0 prints
@pytest.mark.parametrize("method, args, dof", [("tlf", SMALL_TLF, 270),
                                               ("lebb", ["--set", "mesh.beam_elements=4"], 24)])
def test_n_beyond_the_model_gives_every_mode_with_a_note(capsys, method, args, dof):
    code, out, err = cli(capsys, "modes", "--method", method, *args, "--n", "2000", "--json")
    assert code == 0, err
    d = json.loads(out)
    assert dof <= d["n"] <= 2 * dof and d["dof"] == dof
    assert len(d["frequencies_hz"]) == d["n"]
    assert d["warnings"] and d["warnings"][0].startswith(f"--n 2000: {method} has {d['n']} modes")
    assert d["stable"] is True


@pytest.mark.serial    # checks the CLI's output, which only rank 0 prints
def test_campbell_speeds_pass_the_rpm_validation(capsys, tmp_path):
    code, out, err = cli(capsys, "modes", "--method", "lebb", "--campbell", "0:1e9:3",
                         "--out", str(tmp_path / "o"))
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fxflex: error: --campbell: ")
    assert "rotation.rpm" in lines[0] and "allowed: below" in lines[0]
    assert list(tmp_path.iterdir()) == []
    # the same limit as --rpm's, not a stricter one: a range up to 60000 rpm is accepted
    code, out, err = cli(capsys, "modes", "--method", "lebb", "--set", "mesh.beam_elements=2",
                         "--campbell", "59000:60000:2", "--n", "2", "--out", str(tmp_path / "o"),
                         "--json")
    assert code == 0, err


@pytest.mark.mpi
def test_two_ranks_keep_the_equilibrium_and_agree_on_no_verdict(capsys, pep_gives_up):
    """Under MPI the PEP fails on every rank together (SLEPc is collective): every rank exits 0,
    rank 0 alone prints the JSON with ``stable: null`` and the warning."""
    from mpi4py import MPI

    code, out, err = cli(capsys, "steady", "--method", "tlf", *SMALL_TLF, "--json")
    assert code == 0
    if MPI.COMM_WORLD.rank == 0:
        d = json.loads(out)
        assert d["stable"] is None and d["converged"] is True
        assert d["warnings"][0].startswith("stability not decided: SLEPc PEP converged ")
    else:
        assert out == ""
