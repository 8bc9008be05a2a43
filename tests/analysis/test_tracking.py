"""Campbell branches tracked by MAC (SPEC section 10, issue 16): the assignment on synthetic
crossing modes, resonance crossings on a synthetic branch, and NEBB / LEBB on the default blade
(a veering: the shapes exchange along the branches) and on the untwisted one (a true crossing:
the sorted order swaps, the branches keep their families); the command line's JSON."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.analysis.modes import campbell_tracked, speed_builder
from fxflex.analysis.tracking import MAC_THRESHOLD, assign, mac_matrix, ordinal, resonances
from fxflex.scene import Scene

COMM = MPI.COMM_WORLD
SPEEDS = np.linspace(0.0, 12000.0, 25)


def tracked(method, speeds=SPEEDS, pairs=6, **changes):
    scene = Scene().replace(**changes) if changes else Scene()
    return campbell_tracked(speed_builder(method, scene, COMM), speeds, pairs, method)


def branch(tr, label):
    return next(b for b in tr.branches if b.label == label)


def test_ordinal():
    assert [ordinal(k) for k in (1, 2, 3, 4, 11, 12, 13, 21, 22, 23, 101)] == [
        "1st", "2nd", "3rd", "4th", "11th", "12th", "13th", "21st", "22nd", "23rd", "101st"]


def test_assignment_follows_two_crossing_modes_where_sorting_swaps_them():
    """Two shapes that turn slowly with the parameter and whose frequencies cross: at each step
    the sorted order swaps them after the crossing, the MAC assignment does not."""
    rng = np.random.default_rng(1)
    M = np.diag(rng.uniform(1.0, 2.0, 8))
    base = np.linalg.qr(rng.standard_normal((8, 2)))[0]
    p = np.linspace(0.0, 1.0, 11)
    freq = np.stack([1.0 + p, 2.0 - p], axis=1)         # cross at p = 0.5
    index = np.array([0, 1])
    X = base * (1.0 + 0.5j)                              # complex, any phase
    for i in range(1, p.size):
        turn = 0.02 * i
        Y = base @ np.array([[math.cos(turn), -math.sin(turn)],
                             [math.sin(turn), math.cos(turn)]])
        order = np.argsort(freq[i])                      # the candidates come sorted
        Y = Y[:, order] * np.exp(1j * rng.uniform(0, 2 * np.pi, 2))
        mac = mac_matrix(X[:, index], M @ X[:, index], Y, M @ Y)
        index = assign(mac)
        assert np.array_equal(order[index], [0, 1]), i   # each branch its own shape
        assert mac[[0, 1], index].min() > 0.99
        X = Y
    assert np.array_equal(np.argsort(freq[-1]), [1, 0])  # sorting would have swapped them


def test_assignment_prefers_the_growing_real_root():
    """Past a divergence two real roots +-a share the shape: the growing one continues."""
    mac = np.array([[0.97, 0.98, 0.1]])
    lam = np.array([5.0 + 0j, -5.0 + 0j, 1j])
    assert assign(mac)[0] == 1 and assign(mac, lam)[0] == 0
    assert assign(np.array([[0.2, 0.9]]), np.array([-1.0 + 0j, -2.0 + 0j]))[0] == 1


def test_resonances_on_a_synthetic_branch():
    """f = 80 + 0.005 rpm (Hz) crosses h rpm / 60 at rpm = 80 / (h / 60 - 0.005): the
    interpolation is exact for a straight branch, on any grid."""
    rpm = np.array([0.0, 700.0, 1900.0, 3100.0, 5000.0, 6000.0, 9000.0])
    got = resonances(rpm, 80.0 + 0.005 * rpm)
    want = sorted(((h, 80.0 / (h / 60.0 - 0.005)) for h in (1, 2, 3, 4)),
                  key=lambda hr: hr[1])
    assert [h for h, _ in got] == [h for h, _ in want]
    np.testing.assert_allclose([r for _, r in got], [r for _, r in want], rtol=1e-12)
    # a frequency that touches the line at a sample counts once; NaN breaks the branch
    assert resonances([0.0, 60.0, 120.0], [2.0, 1.0, 0.5], harmonics=(1,)) == [(1, 60.0)]
    assert resonances([0.0, 60.0, 120.0], [2.0, np.nan, 0.5], harmonics=(1,)) == []


@pytest.fixture(scope="module")
def nebb_default():
    return tracked("nebb")


def test_default_blade_branches_are_the_roots_and_keep_mac(nebb_default):
    """Default (twisted) blade, NEBB, 0 to 12000 rpm: after refinement every branch's MAC to the
    previous speed is >= 0.9; at each speed the branches take distinct roots of that speed's
    eigensolve, at the first the lowest ones; SPEC section 10's labels and ratios."""
    tr = nebb_default
    assert tr.low_mac() == [] and set(SPEEDS) <= set(tr.rpm)
    assert np.all(np.diff(tr.rpm) > 0) and tr.refined == tr.rpm.size - SPEEDS.size
    for b in tr.branches:
        assert b.mac[0] == 1.0 and np.all(b.mac[1:] >= MAC_THRESHOLD)
        assert b.frequencies_hz.size == tr.rpm.size
    for i, s in enumerate(tr.samples):
        idx = [b.index[i] for b in tr.branches]
        assert len(set(idx)) == len(idx) and min(idx) >= 0
        for b in tr.branches:
            assert b.eigenvalues[i] == s.lam[b.index[i]]
    first = sorted(b.frequencies_hz[0] for b in tr.branches)
    np.testing.assert_array_equal(first, np.sort(tr.samples[0].modes.frequencies_hz))
    assert [b.label for b in tr.branches][:4] == [
        "1st out-of-plane", "1st in-plane", "2nd out-of-plane", "2nd in-plane"]
    b = tr.branches[0]
    np.testing.assert_allclose(b.damping_ratios, -b.growth_rates / np.abs(b.eigenvalues))


def test_default_blade_flap_and_edge_veer(nebb_default):
    """Flap 1 and edge 1 of the twisted blade do not cross: they veer (5000-7000 rpm), the
    shapes exchanging gradually along each branch (neighbouring MAC >= 0.92 at 500 rpm steps),
    so each branch keeps its label and its place in frequency while its tip turns to the other
    family; the MAC between a branch's ends is below 0.1. (The sorted labels of the untracked
    diagram change at 6000 rpm for this reason, not by a swap of modes.)"""
    tr = nebb_default
    flap, edge = branch(tr, "1st out-of-plane"), branch(tr, "1st in-plane")
    assert np.all(flap.frequencies_hz < edge.frequencies_hz)
    assert (flap.directions[0], flap.directions[-1]) == ("out-of-plane", "in-plane")
    assert (edge.directions[0], edge.directions[-1]) == ("in-plane", "out-of-plane")
    s0, s1 = tr.samples[0], tr.samples[-1]
    i0, i1 = flap.index[0], flap.index[-1]
    ends = mac_matrix(s0.X[:, [i0]], s0.MX[:, [i0]], s1.X[:, [i1]], s1.MX[:, [i1]])
    assert ends[0, 0] < 0.1


def test_untwisted_blade_flap_and_edge_cross_and_keep_their_families():
    """Without twist flap and edge are uncoupled and cross near 5800 rpm: the sorted order
    swaps them, the tracked branches keep their tip family at both ends."""
    tr = tracked("nebb", **{"geometry.twist_deg": 0.0})
    flap, edge = branch(tr, "1st out-of-plane"), branch(tr, "1st in-plane")
    assert tr.low_mac() == []
    assert set(flap.directions) == {"out-of-plane"} and set(edge.directions) == {"in-plane"}
    assert flap.frequencies_hz[0] < edge.frequencies_hz[0]
    assert flap.frequencies_hz[-1] > edge.frequencies_hz[-1]
    assert (flap.index[0], flap.index[-1]) == (0, 1)       # sorting would swap the labels


def test_lebb_divergence_and_refinement():
    """LEBB on the default blade at 2500 rpm steps: the step from 5000 to 7500 rpm crosses the
    veering and the divergence (MAC about 0.5), so it is bisected; past the divergence the
    growing real root continues its branch."""
    tr = tracked("lebb", np.linspace(0.0, 10000.0, 5), 4)
    assert tr.refined > 0 and tr.low_mac() == []
    added = tr.rpm[~tr.requested]
    assert np.all((added > 5000.0) & (added < 7500.0))
    lowest = tr.branches[0]
    assert lowest.frequencies_hz[-1] == 0.0 and lowest.growth_rates[-1] > 700.0
    assert lowest.damping_ratios[-1] == -1.0


@pytest.mark.serial     # spawns the CLI
def test_campbell_json_and_text(tmp_path):
    r = subprocess.run([sys.executable, "-m", "fxflex", "modes", "--method", "lebb",
                        "--campbell", "0:12000:13", "--n", "4", "--out", str(tmp_path / "o"),
                        "--json"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["campbell"]["rpm"] == [1000.0 * k for k in range(13)]   # the requested speeds
    assert set(d["campbell"]["rpm"]) <= set(d["rpm"]) and len(d["branches"]) == 4
    for b in d["branches"]:
        assert {"label", "family", "frequencies_hz", "growth_rates", "damping_ratios",
                "mac"} <= set(b)
        assert all(len(b[k]) == len(d["rpm"]) for k in ("frequencies_hz", "growth_rates",
                                                        "damping_ratios", "mac"))
        assert b["mac"][0] == 1.0
    labels = {b["label"] for b in d["branches"]}
    assert d["resonances"] and all(r["branch"] in labels and r["harmonic"] in (1, 2, 3, 4)
                                   and 0 < r["rpm"] < 12000 for r in d["resonances"])
    rows = (tmp_path / "o" / "campbell_lebb_branches.csv").read_text().splitlines()
    assert len(rows) == 1 + 4 * len(d["rpm"])
    text = subprocess.run([sys.executable, "-m", "fxflex", "modes", "--method", "lebb",
                           "--campbell", "0:12000:13", "--n", "4", "--out",
                           str(tmp_path / "t")], capture_output=True, text=True)
    assert "resonances" in text.stdout and "1x  1st out-of-plane" in text.stdout


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_tlf_mass_products_are_the_linearisation_mass(mass):
    """TLF's MAC weight, ``mass_apply`` on the free coordinates, is the mass matrix of its
    linearisation (assembled again here), on any number of ranks."""
    from fxflex.analysis.tracking import mass_times
    from fxflex.formulation import BuildOptions, build
    from fxflex.scene import load_scene

    scene = load_scene(overrides=["mesh.solid=[10,2,2]", "rotation.rpm=3000"])
    form = build("tlf", scene, COMM, BuildOptions(mass=mass))
    lam, X = form.rotating_modes(4)
    MX = mass_times(form, X)
    M, C, K = form.linearisation()._reassemble()
    x, y = M.createVecs()
    ref = np.empty_like(X)
    for j in range(X.shape[1]):
        parts = []
        for part in (X[:, j].real, X[:, j].imag):
            x.getArray()[:] = part
            M.mult(x, y)
            parts.append(y.getArray().copy())
        ref[:, j] = parts[0] + 1j * parts[1]
    for A in (M, C, K, x, y):
        A.destroy()
    scale = COMM.allreduce(np.abs(ref).max(), op=MPI.MAX)
    assert np.abs(MX - ref).max() <= 1e-12 * scale
    mac = mac_matrix(X, MX, X, MX, form.comm)
    np.testing.assert_allclose(np.diag(mac), 1.0, rtol=1e-12)


def test_api_campbell_gives_the_tracked_branches():
    """fxflex.campbell follows the modes by MAC as ``modes --campbell`` does (the same
    computation: campbell_tracked on speed_builder); progress once per requested speed."""
    import fxflex

    speeds = np.linspace(0.0, 12000.0, 7)
    seen = []
    data = fxflex.campbell("lebb", speeds, n=4, comm=COMM,
                           progress=lambda i, m: seen.append((i, m.rpm)))
    ref = tracked("lebb", speeds, 4)
    assert data.tracking.to_dict() == ref.to_dict()
    assert data.tracking.refined > 0                 # LEBB's divergence refines the step
    assert seen == [(i, rpm) for i, rpm in enumerate(speeds)]
    assert list(data.rpm) == list(speeds) and [m.rpm for m in data.modes] == list(speeds)
    for m, s in zip(data.modes, (s for s in ref.samples if s.requested)):
        assert np.array_equal(m.eigenvalues, s.modes.eigenvalues)
    plain = fxflex.campbell("lebb", speeds[::-1], n=4, comm=COMM, track=False)
    assert plain.tracking is None and [m.rpm for m in plain.modes] == list(speeds[::-1])
    with pytest.raises(fxflex.FxflexError, match="increasing speeds, or track=False"):
        fxflex.campbell("lebb", speeds[::-1], n=4, comm=COMM)


@pytest.mark.serial     # spawns the CLI
def test_api_campbell_branches_are_the_cli_s(tmp_path):
    import fxflex

    r = subprocess.run([sys.executable, "-m", "fxflex", "modes", "--method", "lebb",
                        "--campbell", "0:12000:7", "--n", "4", "--out", str(tmp_path),
                        "--json"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    cli = json.loads(r.stdout)
    api = fxflex.campbell("lebb", np.linspace(0.0, 12000.0, 7), n=4).tracking.to_dict()
    assert cli["rpm"] == api["rpm"]              # the same refined speeds
    assert [(b["label"], b["directions"]) for b in cli["branches"]] == [
        (b["label"], b["directions"]) for b in api["branches"]]
    # two processes, the same dense eigensolve: equal far beyond what the tracking resolves
    for b, c in zip(cli["branches"], api["branches"]):
        np.testing.assert_allclose(b["frequencies_hz"], c["frequencies_hz"], rtol=1e-7)
        np.testing.assert_allclose(b["mac"], c["mac"], rtol=0, atol=1e-7)
    assert [(x["branch"], x["harmonic"]) for x in cli["resonances"]] == [
        (x["branch"], x["harmonic"]) for x in api["resonances"]]
