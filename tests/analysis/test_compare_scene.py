"""fxflex compare on a scene that is not the paper's (issue 14 item 4): a NACA 2412 blade runs the
same studies as the paper's scene, all six methods side by side, and every SPEC section 7 row
carries ours with the paper's figure marked not applicable (report, results, paper.csv)."""

import csv

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.analysis.compare import run_compare
from fxflex.analysis.compare_paper import (NOT_APPLICABLE, not_applicable,
                                           paper_scene_differences)
from fxflex.formulation import build
from fxflex.scene import METHODS, PAPER_RPM, Scene, load_scene

AIRFOIL = ['geometry.section="naca4"', 'geometry.airfoil="2412"', "mesh.solid=[6,4,2]",
           "mesh.beam_elements=4"]
#: study 1b's accurate solids, small for the test
ACCURATE = {"mesh.solid_degree": 2, "mesh.solid": (4, 4, 2)}
#: rows of every kind that the paper's scene reports with all six methods (by label start)
ROWS = ["LEBB vs FFRF, orthogonal", "GCMS vs FFRF, load", "NEBB vs TLF, load",
        "ANCF vs TLF, orthogonal", "Omega1: TLF orthogonal smaller", "FFRF load increase",
        "TLF longitudinal 10000 rpm", *[f"{m.upper()} converges at Omega3: transient"
                                        for m in METHODS],
        *[f"{m.upper()} converges at Omega3: stable" for m in METHODS],
        "Relative model: convergent deflection independent of c",
        "Absolute model, Omega3", "Sect. 4.2: ANCF-CD", "Sect. 4.2: NEBB-AB",
        "Fig. 5: half the paper step"]


def test_which_scenes_are_the_papers():
    """Meshes, degrees, variants and modes keep the paper's figures applicable; another body,
    material, load, tip mass or an imported mesh does not."""
    assert paper_scene_differences(Scene()) == []
    same_body = load_scene(overrides=["mesh.solid=[10,2,2]", "mesh.solid_degree=2",
                                      'mesh.beam_variant="locking-free"', "rotation.rpm=5000",
                                      "damping.c=100", "reduction.ffrf_modes=12"])
    assert paper_scene_differences(same_body) == []
    for key in ('geometry.section="ellipse"', "geometry.twist_deg=0", "material.E=70e9",
                "load.line_load=-100", "tip_mass.mass=1", "geometry.hub_radius=0.1"):
        diff = paper_scene_differences(load_scene(overrides=[key]))
        assert [d.split(" = ")[0] for d in diff] == [key.split("=")[0]], key
    rows = [{"figure": "x", "ours": 1.5, "paper": 1.3, "kind": "bound", "pass": False},
            {"figure": "y", "ours": 2.0, "paper": 1.0, "kind": "value", "pass": True,
             "q1_ours": 3.0, "q1_pass": False, "locking": True}]
    marked = not_applicable(rows)
    assert [f["ours"] for f in marked] == [1.5, 2.0]
    assert [f["paper_on_its_scene"] for f in marked] == [1.3, 1.0]
    assert all(f["paper"] == NOT_APPLICABLE and f["pass"] is None for f in marked)
    assert marked[1]["q1_pass"] is None and marked[1]["locking"] is False


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("compare_airfoil")
    lines = []
    scene = load_scene(overrides=AIRFOIL)
    res = run_compare(scene, list(METHODS), str(out), MPI.COMM_WORLD, progress=lines.append,
                      paper_window=3e-4,
                      tlf_windows={"speeds": 1e-4, "steps": 5e-5, "damping": 5e-5},
                      accurate=ACCURATE)
    return scene, res, out, lines


def test_same_studies_on_the_airfoil_with_the_papers_figures_not_applicable(study):
    scene, res, _, _ = study
    assert res["finished"] is True and res["paper_scene"] is False
    assert {d.split(" = ")[0] for d in res["scene_differences"]} == {"geometry.section",
                                                                     "geometry.airfoil"}
    # the same studies as on the paper's scene: three speeds and the damping grid per method
    assert sorted((r["method"], r["rpm"]) for r in res["steady"]) == \
        sorted((m, rpm) for m in METHODS for rpm in PAPER_RPM)
    assert len(res["damping_steady"]) == len(METHODS) * 2 * 2 * 3
    assert {t["study"] for t in res["transients"]} == {"speeds", "steps", "damping"}
    assert set(res["efficiency"]) == {"tlf", "nebb", "ancf"}
    assert res["accurate_solids"] is not None
    for label in ROWS:
        assert any(f["figure"].startswith(label) for f in res["paper"]), label
    for f in res["paper"] + res["accurate_solids"]["paper"]:
        assert f["paper"] == NOT_APPLICABLE and f["pass"] is None, f["figure"]
        assert f["applicable"] is False and f["paper_on_its_scene"] is not None
        assert f["ours"] is not None
    # every method decided its stability at every speed (the eigenvalue analysis runs here too)
    assert all(r["stable"] is not None for r in res["steady"])


def test_equilibria_are_the_airfoils(study):
    """The report's equilibria are those of the airfoil scene itself, not the paper's
    rectangle: NEBB's and TLF's at 1000 rpm against a direct build (the same Newton solves to
    their tolerances: 1e-8 of the deflection is far above their residual floors)."""
    scene, res, _, _ = study
    for m in ("nebb", "tlf"):
        row = next(r for r in res["steady"] if (r["method"], r["rpm"]) == (m, PAPER_RPM[0]))
        st = build(m, scene.replace(**{"rotation.rpm": PAPER_RPM[0]}),
                   MPI.COMM_WORLD).steady_state()
        tip = 1e3 * np.asarray(st.tip)
        assert np.allclose(row["tip_mm"], tip, rtol=0, atol=1e-8 * np.abs(tip).max()), m
        paper = build(m, Scene().replace(**{"rotation.rpm": PAPER_RPM[0],
                                            "mesh.solid": (6, 4, 2), "mesh.beam_elements": 4}),
                      MPI.COMM_WORLD).steady_state()
        assert np.abs(1e3 * np.asarray(paper.tip) - tip).max() > 0.1 * np.abs(tip).max(), m


@pytest.mark.serial
def test_report_and_paper_csv_mark_the_figures(study):
    _, res, out, lines = study
    report = (out / "report.md").read_text()
    assert "**Not the paper's scene**" in report and "geometry.section" in report
    section2 = report.split("## 2. SPEC section 7")[1].split("\n## ")[0]
    body = [row for row in section2.splitlines() if row.startswith("| ")][1:]
    assert len(body) == len(res["paper"])
    for row in body:
        cells = [c.strip() for c in row.strip("| ").split(" | ")]
        assert cells[2] == NOT_APPLICABLE and cells[3] == "n/a" and cells[4] == "n/a", row
    assert "FAIL" not in section2
    with open(out / "paper.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(res["paper"])
    assert all(r["paper"] == NOT_APPLICABLE and r["how"] == "n/a" and r["pass"] == ""
               for r in rows)
    # ours in the CSV are the results' (the side-by-side figures are kept)
    ours = {f["figure"]: f["ours"] for f in res["paper"]}
    for r in rows:
        if isinstance(ours[r["figure"]], float):
            assert float(r["ours"]) == pytest.approx(ours[r["figure"]], rel=1e-9)
    assert any(t.startswith("estimate:") for t in lines)
