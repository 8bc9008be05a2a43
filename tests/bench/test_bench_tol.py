"""``fxflex bench tol``: its own references (Richardson on a ladder), the candidate pruning, and
the quick study with resume from its JSON."""

import json

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.bench import tol
from fxflex.scene import load_scene

COMM = MPI.COMM_WORLD


def _level(n, value, modes=None, mesh=None):
    return {"discretisation": {"mesh": mesh, "degree": None, "modes": modes,
                               "elements": None if mesh else n, "variant": None},
            "dof": 3 * n, "tip_m": list(value)}


def test_own_reference_recovers_a_manufactured_limit():
    """f = f* + c h^p on elements 4, 8, 16, 32 (p = 2 and 1.5): Richardson on the finest three
    gives f* to round-off (the sequence is exact), and the uncertainty (the triple before) is
    exact too; a non-monotone quantity keeps the finest value and its last change."""
    h = 1.0 / np.array([4, 8, 16, 32])
    f = np.stack([1.0 + 0.3 * h**2, -2.0 + 0.05 * h**1.5, 1.0 + 1e-3 * (-1.0) ** np.arange(4)],
                 axis=1)
    ref = tol.own_reference([_level(n, v) for n, v in zip((4, 8, 16, 32), f)], "tip_m")
    assert ref["value"][:2] == pytest.approx([1.0, -2.0], rel=1e-12, abs=1e-12)
    assert max(ref["error"][:2]) < 1e-12
    assert ref["value"][2] == f[-1, 2] and ref["error"][2] == pytest.approx(2e-3)
    assert ref["order"][0] == pytest.approx(2.0, rel=1e-8)
    assert ref["finest"] == "elements 32"


def test_mode_count_levels_replace_their_mesh_level():
    """FFRF-like ladder: a mode-count level on the mesh before it stands for that mesh; with only
    two meshes there is no reference."""
    levels = [_level(8, [1.0], 30, [8, 2, 2]), _level(16, [0.9], 30, [16, 2, 2]),
              _level(16, [0.8], 60, [16, 2, 2])]
    mesh = tol._mesh_levels(levels)
    assert [lv["discretisation"]["modes"] for lv in mesh] == [30, 60]
    with pytest.raises(Exception, match="three mesh levels"):
        tol.own_reference(levels, "tip_m")


def test_true_errors_scale():
    ref = [3.0, 4.0, 0.0]
    assert tol.true_errors([3.5, 4.0, 0.0], ref, "steady") == pytest.approx([0.1, 0.0, 0.0])
    assert tol.true_errors([11.0, 19.0], [10.0, 20.0], "modes") == pytest.approx([0.1, 0.05])


@pytest.mark.serial       # rank 0 writes tol.json into its own tmp_path; the checks read it
def test_quick_study_is_within_eps_and_resumes(tmp_path, monkeypatch):
    """The smoke study (LEBB and TLF steady at EPS = 1e-2, 1000 rpm; LEBB modes): every result is
    within EPS of its reference (stored for TLF, own refinement for LEBB) and within 3x of its
    estimate once the reference's own uncertainty is taken off; a second run computes nothing
    (every row from tol.json) and reports the same."""
    first = tol.run(load_scene(), str(tmp_path), COMM, quick=True)
    rows = first["steady"] + first["modes"]
    assert len(first["steady"]) == 2 and len(first["modes"]) == 1
    for r in rows:
        assert r["within_eps"], r["method"]
        assert r["resolved_ratio"] <= tol.RATIO_BOUND, r["method"]
        assert max(r["estimate"]) < r["eps"]
    tlf = next(r for r in first["steady"] if r["method"] == "tlf")
    assert "stored" in tlf["reference_source"] and tlf["cheapest"] is not None
    data = json.loads((tmp_path / "tol.json").read_text())
    assert {"steady lebb 1000 0.01", "reference steady lebb 1000",
            "candidates tlf 1000"} <= set(data["rows"])

    def fail(*args, **kwargs):
        raise AssertionError("recomputed a stored row")

    monkeypatch.setattr(tol, "_tol_row", fail)
    monkeypatch.setattr(tol, "candidates", fail)
    monkeypatch.setattr(tol, "own_reference", fail)
    second = tol.run(load_scene(), str(tmp_path), COMM, quick=True)
    assert second["summary"].splitlines()[0] == first["summary"].splitlines()[0]
    assert (tmp_path / "tol.md").exists() and (tmp_path / "tol.png").exists()
