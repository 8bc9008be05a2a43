"""fxflex compare: every study on a coarse scene with short windows, the SPEC section 7 rows,
the damping models, the files, and --full's estimate."""

import json
import subprocess
import sys

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.analysis.compare import SAMPLE_DT, SteadyRow, paper_rows, plan, run_compare
from fxflex.io.series import read_series
from fxflex.scene import METHODS, PAPER_DAMPING, PAPER_RPM, load_scene

COARSE = ["mesh.solid=[10,2,2]", "mesh.beam_elements=4"]
#: study 1b's accurate solids, small for the test
ACCURATE = {"mesh.solid_degree": 2, "mesh.solid": (8, 2, 2)}
#: every SPEC section 7 figure the report must carry when all six methods run (by label start)
SPEC7 = ["LEBB vs FFRF, longitudinal", "LEBB vs FFRF, orthogonal", "LEBB vs FFRF, load",
         "GCMS vs FFRF, longitudinal", "GCMS vs FFRF, orthogonal", "GCMS vs FFRF, load",
         "NEBB vs TLF, longitudinal", "NEBB vs TLF, orthogonal",
         "NEBB vs TLF, load", "ANCF vs TLF, longitudinal", "ANCF vs TLF, orthogonal",
         "ANCF vs TLF, load", "Omega1: TLF orthogonal smaller", "Omega1: TLF load smaller",
         "Omega2: TLF orthogonal smaller", "Omega2: TLF load smaller",
         "FFRF orthogonal increase", "FFRF load increase", "TLF orthogonal decrease",
         "TLF load decrease", "TLF longitudinal 5000 rpm", "TLF longitudinal 10000 rpm",
         *[f"{m.upper()} converges at Omega3: transient" for m in METHODS],
         *[f"{m.upper()} converges at Omega3: stable" for m in ("ffrf", "gcms", "lebb", "nebb",
                                                               "ancf")],
         "Relative model: convergent deflection independent of c",
         "Absolute model: convergent orthogonal deflection depends on c",
         "Absolute model, Omega1", "Absolute model, Omega3",
         "Sect. 4.2: ANCF-CD", "Sect. 4.2: TLF-CD", "Sect. 4.2: NEBB-AB"]

#: the rows whose verdict holds on any mesh and window, so the coarse study must pass them: the
#: stability of each method's equilibrium at Omega3 (linear models unstable, nonlinear stable) and
#: the damping models' equilibria (relative: c does not enter; absolute: a drag linear in c)
DECIDED = [*[f"{m.upper()} converges at Omega3: stable" for m in METHODS],
           "Relative model: convergent deflection independent of c",
           "Absolute model: convergent orthogonal deflection depends on c",
           "Absolute model, Omega1: orthogonal deflection slightly decreases",
           "Absolute model, Omega3: |orthogonal| grows with c"]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("compare")
    lines = []
    res = run_compare(load_scene(overrides=COARSE), list(METHODS), str(out), MPI.COMM_WORLD,
                      progress=lines.append, paper_window=4e-4,
                      tlf_windows={"speeds": 2e-4, "steps": 1e-4, "damping": 1e-4},
                      accurate=ACCURATE)
    return res, out, lines


@pytest.mark.serial
def test_report_has_every_spec_row_with_ours_and_the_paper(study):
    res, out, lines = study
    report = (out / "report.md").read_text()
    figures = {f["figure"]: f for f in res["paper"]}
    for label in SPEC7:
        hits = [f for name, f in figures.items() if name.startswith(label)]
        assert hits, label
        for f in hits:
            row = next(r for r in report.splitlines() if r.startswith("| " + f["figure"]
                                                                     .replace("|", "\\|")))
            cells = [c.strip() for c in row.split(" | ")]
            assert cells[2] == str(f["paper"])
            assert cells[-1].rstrip(" |") == {True: "pass", False: "FAIL", None: "-"}[f["pass"]]
    for f in res["paper"]:
        rule = _rule(f)
        assert rule is None or f["pass"] is rule, f["figure"]
    for label in DECIDED:
        hits = [f for f in res["paper"] if f["figure"].startswith(label)]
        assert hits and all(f["pass"] is True for f in hits), label
    assert res["finished"] is True and any(t.startswith("estimate:") for t in lines)


def _rule(f):
    """The verdict of a row whose kind compares ours with the paper's number (paper_rows, HOW),
    or None for the kinds whose verdict is not a function of those two alone."""
    ours, paper, kind = f["ours"], f["paper"], f["kind"]
    if kind == "value":
        return abs(ours - paper) <= 1.0
    if kind == "bound":
        return ours <= paper
    if kind == "approximate":
        return abs(ours / paper - 1) <= 0.1
    if kind == "verdict":
        return ours == paper
    return None


@pytest.mark.serial
def test_files_plots_and_series(study):
    res, out, _ = study
    for name in ("steady.csv", "damping_steady.csv", "transients.csv", "paper.csv"):
        assert len((out / name).read_text().splitlines()) > 1, name
    assert len((out / "steady.csv").read_text().splitlines()) == 1 + 6 * 3
    assert len((out / "damping_steady.csv").read_text().splitlines()) == 1 + 6 * 2 * 2 * 3
    for fig in res["figures"]:
        assert (out / fig).read_bytes()[:4] == b"\x89PNG"
    assert {"fig4_1000rpm.png", "fig5_steps.png", "fig11_absolute_10000rpm.png",
            "drive_torque.png", "damping_steady.png"} <= set(res["figures"])
    cases = plan(list(METHODS), False)
    series = sorted(p.name for p in (out / "series").iterdir())
    assert len(series) == len({c.key for cs in cases.values() for c in cs})
    meta, columns, data = read_series(out / "series" / series[0])
    assert columns[:4] == ["t_s", "longitudinal_m", "orthogonal_m", "load_m"]
    assert columns[-2:] == ["sigma_root_max_Pa", "sigma_root_min_Pa"] and len(data) > 2
    assert meta["method"] in METHODS
    assert json.loads((out / "results.json").read_text())["finished"] is True
    # a run that diverged stopped early; the others reached their window (to within a sample)
    assert all(s["diverged"] or s["t_reached_s"] >= s["case"]["t_end"] - SAMPLE_DT
               - s["case"]["dt"] for s in res["transients"])


@pytest.mark.serial
def test_damping_models(study):
    """Relative damping: the equilibrium does not move with c. Absolute: the damping of the
    rotating body's absolute velocity is a drag c Omega x r against the rotation, linear in c, so
    the orthogonal deflection moves linearly with c: it decreases at Omega1 and grows in magnitude
    at Omega3, for every method (Sect. 4.3)."""
    res, _, _ = study
    rows = res["damping_steady"]
    c = np.array(sorted(PAPER_DAMPING))
    for m in METHODS:
        for rpm in (PAPER_RPM[0], PAPER_RPM[2]):
            rel = np.array([r["tip_mm"] for r in rows if (r["method"], r["rpm"], r["model"])
                            == (m, rpm, "relative")])
            absd = np.array([r["tip_mm"][1] for r in sorted(rows, key=lambda r: r["c"])
                             if (r["method"], r["rpm"], r["model"]) == (m, rpm, "absolute")])
            # c does not enter the relative model's equilibrium equations: equal to round-off
            assert len(rel) == 3 and np.ptp(rel, axis=0).max() <= 1e-12 * np.abs(rel).max()
            steps = np.diff(absd)
            if rpm == PAPER_RPM[0]:
                assert np.all(steps < 0), (m, rpm, absd)
            else:
                assert np.all(np.diff(np.abs(absd)) > 0), (m, rpm, absd)
            # linear in c: the structure's response to the drag is linear to O(|u| / L) < 1e-3
            np.testing.assert_allclose(steps[1] / steps[0], (c[2] - c[1]) / (c[1] - c[0]),
                                       rtol=1e-2, err_msg=f"{m} {rpm}")
    def row(start):
        return next(f for f in res["paper"] if f["figure"].startswith(start))

    assert row("Relative model: convergent deflection independent of c")["pass"] is True
    assert row("Absolute model: convergent orthogonal deflection depends")["pass"] is True
    assert row("Absolute model, Omega3: |orthogonal| grows with c")["pass"] is True


def test_paper_rows_arithmetic():
    o1, o2, _ = PAPER_RPM
    rows = [SteadyRow("ffrf", o1, np.array([1.0, -1.0, -2.0]), None, True, 1, 0.0),
            SteadyRow("tlf", o1, np.array([1.0, -0.8, -1.0]), None, True, 1, 0.0),
            SteadyRow("ffrf", o2, np.array([1.0, -3.0, -2.5]), None, True, 1, 0.0),
            SteadyRow("tlf", o2, np.array([1.0, -0.4, -0.75]), None, True, 1, 0.0)]
    got = {f["figure"]: f["ours"] for f in paper_rows(rows)}
    assert got["Omega1: TLF orthogonal smaller than FFRF (%)"] == pytest.approx(20.0)
    assert got["Omega1: TLF load smaller than FFRF (%)"] == pytest.approx(50.0)
    assert got["FFRF orthogonal increase Omega1->Omega2 (%)"] == pytest.approx(200.0)
    assert got["TLF load decrease Omega1->Omega2 (%)"] == pytest.approx(25.0)


@pytest.mark.serial
def test_full_prints_its_estimate_first(tmp_path):
    r = subprocess.run([sys.executable, "-m", "fxflex", "compare", "--full", "--methods", "lebb",
                        "--out", str(tmp_path / "c"), "--json", *sum((["--set", s] for s in
                                                                     COARSE), [])],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    err = r.stderr
    assert "estimate:" in err and err.index("estimate:") < err.index("[2/6]")
    d = json.loads(r.stdout)
    assert d["full"] is True and d["windows"]["tlf_s"] is None
    assert d["estimate"]["runs"] == 5 and d["estimate"]["total_s"] > 0
    assert {s["case"]["t_end"] for s in d["transients"]} == {0.02}


@pytest.mark.serial
def test_quadratic_solids_compare_without_the_refused_invariant_route(tmp_path):
    """``fxflex compare --set mesh.solid_degree=2`` (issue 13): TLF's invariant route refuses Q2,
    so the efficiency spot check says so for TLF instead of stopping the study; the rest runs."""
    lines = []
    res = run_compare(load_scene(overrides=["mesh.solid=[6,2,2]", "mesh.solid_degree=2"]),
                      ["tlf", "nebb"], str(tmp_path), MPI.COMM_WORLD, progress=lines.append,
                      paper_window=1e-4, tlf_windows={"speeds": 5e-5, "steps": 5e-5,
                                                      "damping": 5e-5})
    eff = res["efficiency"]
    assert "mesh.solid_degree = 2" in eff["tlf"]["skipped"] and "ratio" not in eff["tlf"]
    assert eff["nebb"]["ratio"] > 0
    assert not any(row["figure"].startswith("Sect. 4.2: TLF") for row in res["paper"])
    assert any(row["figure"].startswith("Sect. 4.2: NEBB") for row in res["paper"])
    assert "not measured: --force-eval invariant" in (tmp_path / "report.md").read_text()
    assert any(line.startswith("  tlf: not measured") for line in lines)


@pytest.mark.serial
def test_accurate_solids_read_the_q1_rows(study):
    """Study 1b (issue 13 item 5): the solids' equilibria again with Q2, and every SPEC row
    decided by equilibria that has a solid in it, with the Q1 figure beside the Q2 one; a row
    is read as the Q1 mesh's locking exactly when it fails with Q1 and passes with Q2."""
    res, out, lines = study
    acc = res["accurate_solids"]
    assert acc["keys"] == {"mesh.solid_degree": 2, "mesh.solid": [8, 2, 2]}
    assert sorted({(s["method"], s["rpm"]) for s in acc["steady"]}) == sorted(
        (m, rpm) for m in ("ffrf", "gcms", "tlf") for rpm in PAPER_RPM)
    own = {f["figure"]: f for f in res["paper"]}
    labels = {f["figure"] for f in acc["paper"]}
    assert "LEBB vs FFRF, orthogonal, Omega1 (|diff| %)" in labels
    assert "Omega1: TLF orthogonal smaller than FFRF (%)" in labels
    assert not any(label.startswith(("Relative model", "Sect. 4.2")) for label in labels)
    for f in acc["paper"]:
        assert f["q1_ours"] == own[f["figure"]]["ours"] and f["ours"] != f["q1_ours"]
        assert f["locking"] == (f["q1_pass"] is False and f["pass"] is True)
    # closer to the converged reference of each one's continuum than the coarse Q1 mesh's
    from fxflex.analysis.reference import relative_error, stored_reference
    from fxflex.bench.accuracy import OWN_THEORY

    ref = stored_reference(load_scene())["theories"]
    steady = {(s["method"], s["rpm"]): s for s in res["steady"]}
    for s in acc["steady"]:
        exact = 1e3 * np.array(ref[OWN_THEORY[s["method"]]][f"{s['rpm']:g}"]["reference_m"])
        q1 = np.array(steady[(s["method"], s["rpm"])]["tip_mm"])
        assert relative_error(s["tip_mm"], exact) < 0.5 * relative_error(q1, exact)
    report = (out / "report.md").read_text()
    assert "## 2b. The rows decided by equilibria, with accurate solids" in report
    assert any(line.startswith("[1b] accurate solids") for line in lines)
    assert (out / "accurate_steady.csv").exists()
