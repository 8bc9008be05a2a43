"""``fxflex bench accuracy``: Pareto fronts, the settling estimate, the quick study."""

import math

import pytest
from mpi4py import MPI

from fxflex.bench.accuracy import pareto, settling
from fxflex.scene import load_scene

COMM = MPI.COMM_WORLD


def test_pareto_front():
    pts = [(1.0, 0.5), (2.0, 0.1), (3.0, 0.2), (0.5, 0.9), (2.0, 0.3), (4.0, 0.01),
           (5.0, math.inf)]
    assert pareto(pts) == [3, 0, 1, 5]


def test_settling_time():
    """ln(100) / 0.0637 = 72.3 s: the paper's transient within 1 % of a unit equilibrium that
    it starts a unit away from."""
    assert settling(1.0, 1.0, 0.0637) == pytest.approx(math.log(100) / 0.0637)
    assert settling(1e-3, 1.0, 0.0637) == 0.0
    assert settling(1.0, 1.0, 0.0) == math.inf


@pytest.mark.paper
@pytest.mark.serial       # rank 0 writes the report into its own tmp_path; the checks read it
def test_bench_accuracy_quick_writes_its_report(tmp_path):
    """The smoke study against the stored reference: every method has its paper route and a
    history study; the Q2 route brings TLF within 1 %, LEBB is within 1 % of the linear
    continuum, and AB2 at the paper step is found never to settle for LEBB (its stiffest root
    grows), while central difference settles for TLF and ANCF."""
    from fxflex.bench.accuracy import run

    result = run(load_scene(), str(tmp_path), COMM, quick=True)
    fastest = result["fastest"]
    assert set(fastest) == {"ffrf", "gcms", "tlf", "lebb", "nebb", "ancf"}
    tlf = fastest["tlf"]
    assert tlf["best"]["route"].startswith("steady Q2") and tlf["best"]["error_own"] < 0.01
    assert fastest["lebb"]["paper_route"]["error_own"] < 0.01
    assert not fastest["lebb"]["paper_route"]["settles"]
    assert fastest["lebb"]["paper_route"]["ab2_rate"] > 0
    for m in ("tlf", "ancf"):
        p = fastest[m]["paper_route"]
        assert p["settles"] and 60 < p["settle_s"] < 200 and p["cost_s"] > 1e2
    names = {p.name for p in (tmp_path).iterdir()}
    assert {"accuracy.md", "accuracy.json", "accuracy_history.png",
            "accuracy_convergent.png"} <= names
    assert "Pareto" in (tmp_path / "accuracy.md").read_text()
