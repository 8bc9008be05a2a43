"""fxflex compare: every method x speed row, the SPEC section 7 figures, files as it goes."""

import json

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.analysis.compare import paper_rows, run_compare
from fxflex.scene import PAPER_RPM, load_scene


@pytest.mark.serial
def test_compare_small_scene(tmp_path):
    scene = load_scene(overrides=["mesh.solid=[10,2,2]", "mesh.beam_elements=4"])
    res = run_compare(scene, ["tlf", "lebb", "nebb"], str(tmp_path), MPI.COMM_WORLD)
    assert [(r["method"], r["rpm"]) for r in res["steady"]] == [
        (m, r) for m in ("tlf", "lebb", "nebb") for r in PAPER_RPM]
    csv = (tmp_path / "steady.csv").read_text().splitlines()
    assert len(csv) == 1 + 9 and csv[0].startswith("method,rpm,longitudinal_m")
    data = json.loads((tmp_path / "results.json").read_text())
    figures = {f["figure"]: f for f in data["paper"]}
    assert "NEBB vs TLF, load, Omega1 (|diff| %)" in figures
    assert figures["LEBB converges at Omega3 (stable equilibrium)"]["ours"] is False
    assert "| figure | ours | paper |" in (tmp_path / "report.md").read_text()


def test_paper_rows_arithmetic():
    class Row:
        def __init__(self, method, rpm, tip):
            self.method, self.rpm, self.tip_m, self.stable = method, rpm, np.array(tip), None

    o1, o2, _ = PAPER_RPM
    rows = [Row("ffrf", o1, [1.0, -1.0, -2.0]), Row("tlf", o1, [1.0, -0.8, -1.0]),
            Row("ffrf", o2, [1.0, -3.0, -2.5]), Row("tlf", o2, [1.0, -0.4, -0.75])]
    got = {f["figure"]: f["ours"] for f in paper_rows(rows)}
    assert got["Omega1: TLF orthogonal smaller than FFRF (%)"] == pytest.approx(20.0)
    assert got["Omega1: TLF load smaller than FFRF (%)"] == pytest.approx(50.0)
    assert got["FFRF orthogonal increase Omega1->Omega2 (%)"] == pytest.approx(200.0)
    assert got["TLF load decrease Omega1->Omega2 (%)"] == pytest.approx(25.0)
