"""``fxflex bench convergence`` (issue 13 item 4): the report's tables, fitted orders, the choice
"which discretisation for 1 %, 0.1 %" and the plots, on rows of known error (the levels
themselves are measured by the benchmark, not here: minutes of CPU)."""

import json
import re

import numpy as np
import pytest

from fxflex.bench import refinement as bench

pytestmark = pytest.mark.serial


def _rows():
    """A Q1 family of error 2 h^2 and a Q2 family of error 0.5 h^3 (h = 8 / n), a beam family
    whose error against the solid levels off at 0.3 % while its own error falls as h^2."""
    rows = []
    for n, cpu in ((8, 0.1), (16, 0.4), (32, 1.6), (64, 6.4)):
        h = 8.0 / n
        rows.append({"case": "iii", "direction": "Z", "method": "tlf", "variant": "",
                     "degree": 1, "level": n, "mesh": [n, 2, 2], "n": n, "dof": 100 * n,
                     "cpu_s": cpu, "error": 0.02 * h**2})
        rows.append({"case": "iii", "direction": "Z", "method": "tlf", "variant": "",
                     "degree": 2, "level": n, "mesh": [n, 2, 2], "n": n, "dof": 400 * n,
                     "cpu_s": 3 * cpu, "error": 0.005 * h**3})
        rows.append({"case": "iii", "direction": "Z", "method": "lebb", "variant": "paper",
                     "degree": 0, "level": n, "n": n, "dof": 6 * n, "cpu_s": cpu / 100,
                     "error": 3e-3 + 1e-3 * h**2, "error_self": 1e-3 * h**2})
    return rows


def test_fitted_orders_and_the_cheapest_discretisation_per_tolerance():
    data = {"info": {"machine": {"cpu": "test"}, "ranks": 1, "quick": False}, "rows": _rows()}
    text, choice = bench.report(data)
    picks = choice["iii"]["tip force Z"]
    # Q1: 0.02 h^2 <= 1e-2 first at h = 0.5 (n = 16); 1e-3 at h <= 0.22: n = 64
    assert picks["tlf Q1"] == {"0.01": "[16, 2, 2] (1600 dof, 0.4 s)",
                               "0.001": "[64, 2, 2] (6400 dof, 6.4 s)"}
    # Q2: 0.005 h^3 <= 1e-2 already at n = 8; <= 1e-3 at h = 0.5 (n = 16)
    assert picks["tlf Q2"] == {"0.01": "[8, 2, 2] (3200 dof, 0.3 s)",
                               "0.001": "[16, 2, 2] (6400 dof, 1.2 s)"}
    # the beam is judged by its own discretisation error, not by the 0.3 % theory gap
    assert picks["lebb"] == {"0.01": "8 el (48 dof, 0.001 s)", "0.001": "8 el (48 dof, 0.001 s)"}
    assert "| tip force Z | tlf Q1 | fitted order |  |  | 2.00 |" in text
    assert "| tip force Z | tlf Q2 | fitted order |  |  | 3.00 |" in text
    assert re.search(r"\| tip force Z \| lebb \| fitted order \|  \|  \| [0-9.]+ \| 2\.00 \|", text)
    assert "## Which discretisation for 1 %, 0.1 %" in text


def test_a_tolerance_no_level_meets_is_reported_as_not_reached():
    rows = [r for r in _rows() if r["degree"] == 1][:2]        # errors 2 % and 0.5 %
    assert bench.cheapest(rows, 1e-3) is None
    text, choice = bench.report({"info": {"machine": {}, "ranks": 1, "quick": True},
                                 "rows": rows})
    assert choice["iii"]["tip force Z"]["tlf Q1"]["0.001"] == "not reached"


def test_plots_and_the_json_store(tmp_path):
    from mpi4py import MPI

    store = bench._Store(str(tmp_path / "convergence.json"), MPI.COMM_SELF, {"quick": True})
    for r in _rows():
        store.add(r)
    assert len(json.loads((tmp_path / "convergence.json").read_text())["rows"]) == 12
    written = bench.plot(store.data, str(tmp_path))
    assert [p.rsplit("/", 1)[1] for p in written] == ["convergence_iii.png"]
    assert (tmp_path / "convergence_iii.png").stat().st_size > 10000
    assert not list(tmp_path.glob("*.tmp*"))


def test_extrapolation_recovers_a_known_limit():
    n = np.array([10, 20, 40])
    tips = np.array([[1.0 + 0.3 / k**2, -2.0 + 0.1 / k**2, 0.0] for k in n])
    ext = bench._extrapolated(n, tips)
    assert ext[:2] == pytest.approx([1.0, -2.0], abs=1e-12)
    assert ext[2] == 0.0                            # no decaying differences: the finest value


def test_spinup_reference_refuses_a_sequence_that_does_not_settle():
    """Case (ii): a theory's answer at a time is extrapolated only where the finest levels'
    in-plane differences shrink monotonically; where they change sign (ANCF's buckling on fine
    meshes) there is none, and a row's error there is taken against NEBB's answer."""
    rows = []
    for n in (10, 20, 40):
        settle = -1.0 + 0.4 / n**2
        wild = -1.0 + (0.4 / n**2 if n < 40 else 0.3)          # jumps at the finest level
        rows.append({"case": "ii", "method": "ancf", "variant": "locking-free", "n": n,
                     "tips": {"2.5": [0.0, settle, 0.0], "7.5": [0.0, wild, 0.0]}})
    ref = bench.spinup_reference(rows)
    assert ref["2.5"][1] == pytest.approx(-1.0, abs=1e-12) and ref["7.5"] is None
    nebb = {"2.5": [0.0, -1.0, 0.0], "7.5": [0.0, -0.5, 0.0]}
    bench.spinup_errors(rows, {"ancf": ref, "nebb": nebb})
    last = rows[-1]
    assert last["errors"]["7.5"] is None
    assert last["errors_vs_nebb"]["7.5"] == pytest.approx(0.4)
    assert last["error"] == pytest.approx(0.4)          # the worst time, NEBB's where none
