"""fxflex bench airfoil (issue 14 validation): the six methods on a NACA 2412 blade at 1000 and
5000 rpm, each against its own Richardson reference, with stability verdicts (--quick levels)."""

import json

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.bench import airfoil
from fxflex.scene import METHODS, Scene


def test_reference_recovers_a_known_expansion():
    """f(h) = f0 + C h^p per component: Richardson's reference is f0 and the order p (to the
    root finder's tolerance), and each level's error is its distance to f0."""
    f0, C, p = np.array([1e-3, -2e-2, -0.12]), np.array([4e-3, 1e-2, -0.3]), (2.0, 1.5, 3.0)
    rows = [{"n": n, "tip_m": (f0 + C * np.array([(1.0 / n) ** q for q in p])).tolist()}
            for n in (10, 20, 40)]
    ref = airfoil.reference(rows)
    assert np.allclose(ref["tip_m"], f0, rtol=1e-8, atol=0)
    assert np.allclose(ref["order"], p, rtol=1e-6)
    tips = np.array([r["tip_m"] for r in rows])
    want = np.linalg.norm(tips - f0, axis=1) / np.linalg.norm(f0)
    assert np.allclose(ref["errors"], want, rtol=1e-6)
    assert ref["errors"][0] > ref["errors"][1] > ref["errors"][2]


def test_blade_keeps_a_users_section():
    assert airfoil.blade(Scene()).geometry.section == "naca4"
    assert airfoil.blade(Scene()).geometry.airfoil == "2412"
    own = Scene().replace(**{"geometry.section": "ellipse"})
    assert airfoil.blade(own) is own


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("airfoil")
    return airfoil.run(Scene(), str(out), MPI.COMM_WORLD, quick=True), out


def test_six_methods_against_their_references(quick):
    res, _ = quick
    refs = res["results"]["references"]
    assert sorted(refs) == sorted(f"{m}@{rpm:g}" for m in METHODS for rpm in airfoil.SPEEDS)
    for key, ref in refs.items():
        # each method converges towards its own reference: the finest level is the closest
        assert ref["errors"][-1] < ref["errors"][0], key
    # stability about each steady state, the same verdict on every level: on this thin blade
    # the small-strain methods (no centrifugal stiffening of the deflected shape) lose
    # stability between 1000 and 5000 rpm, with growth rates of hundreds of 1/s, while the
    # nonlinear ones stay stable (all decay at about c / (2 rho), 0.064 1/s)
    for m in METHODS:
        assert refs[f"{m}@1000"]["stable"] == [True] * 3, m
        expect = m not in ("ffrf", "gcms", "lebb")
        assert refs[f"{m}@5000"]["stable"] == [expect] * 3, m
    # GCMS is FFRF's theory in other coordinates: the same references up to the level error
    for rpm in airfoil.SPEEDS:
        gap = next(g for g in res["results"]["gaps"] if (g["rpm"], g["method"], g["against"])
                   == (rpm, "gcms", "ffrf"))
        assert gap["norm_pct"] < 100 * refs[f"ffrf@{rpm:g}"]["errors"][-1]


@pytest.mark.serial
def test_files_written(quick):
    """airfoil.json (rank 0 writes it into its own folder) holds every row, and the report."""
    _, out = quick
    data = json.loads((out / "airfoil.json").read_text())
    assert len(data["rows"]) == len(METHODS) * len(airfoil.SPEEDS) * 3
    assert "Diagnosis" in (out / "airfoil.md").read_text()
    # the blade studied, not the user's rectangle, is the scene of the JSON (the envelope of
    # `fxflex bench airfoil --json` takes the returned scene) and of the file
    res, _ = quick
    assert res["scene"] == airfoil.blade(Scene())
    assert data["info"]["scene"] == res["scene"].to_dict()
