"""ElastoDyn mode-shape polynomials (SPEC section 10) against the closed-form cantilever modes,
and ``fxflex modes --elastodyn FILE`` through the command line (file, JSON, refusals)."""

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy.optimize import brentq

from fxflex.analysis.elastodyn import (POWERS, SHAPES, choose_modes, elastodyn_section,
                                       fit_mode_shape, missing_shapes, polynomial,
                                       write_elastodyn)
from fxflex.analysis.modes import EXPORT_PAIRS, Modes, modes_for_export
from fxflex.analysis.shapes import FAMILIES, Shapes, trapezoid_weights

FXFLEX = [sys.executable, "-m", "fxflex"]
#: the uniform untwisted cantilever at rest of tests/analysis/test_shapes.py (L / h = 50)
UNIFORM = ["geometry.root_y=0.04", "geometry.tip_y=0.04", "geometry.root_z=0.02",
           "geometry.tip_z=0.02", "geometry.twist_deg=0", "rotation.rpm=0", "load.line_load=0"]


def cantilever_mode(n: int, xi: np.ndarray) -> np.ndarray:
    """The n-th Euler-Bernoulli clamped-free bending mode at xi = x / L (unit length)."""
    guess = (2 * n - 1) * np.pi / 2
    bl = brentq(lambda b: 1 + np.cos(b) * np.cosh(b), guess - 0.6, guess + 0.6)
    s = (np.cosh(bl) + np.cos(bl)) / (np.sinh(bl) + np.sin(bl))
    b = bl * xi
    return np.cosh(b) - np.cos(b) - s * (np.sinh(b) - np.sin(b))


@pytest.mark.parametrize("n", [1, 2])
def test_fit_of_the_cantilever_modes(n):
    x = np.linspace(0.0, 2.5, 41)                 # a 2.5 m blade, 40 beam elements
    fit = fit_mode_shape(x, -3.0 * cantilever_mode(n, x / 2.5), name="shape")
    assert np.sum(fit.coefficients) == pytest.approx(1.0, abs=1e-12)
    exact = cantilever_mode(n, x / 2.5) / cantilever_mode(n, np.array([1.0]))[0]
    misfit = polynomial(fit.coefficients, x / 2.5) - exact
    rms = np.sqrt(np.trapz(misfit**2, x / 2.5))
    assert fit.residual == pytest.approx(rms, rel=1e-6)
    # the polynomial's own error (no round-off involved): 1.5e-6 for mode 1, 3.0e-4 for mode 2
    # (the series of the modes go on with xi^7 (beta L)^7 / 2520, beta L = 1.875, 4.694), 2.2e-2
    # for mode 3, which the six terms cannot follow
    assert fit.residual < {1: 1e-5, 2: 2e-3}[n]
    assert abs(polynomial(fit.coefficients, 0.5) - exact[20]) < 5 * fit.residual


def test_polynomial_data_is_fitted_exactly():
    c = np.array([0.3, 1.2, -0.9, 0.5, -0.1])
    x = np.sort(np.random.default_rng(1).uniform(0.0, 1.0, 30))
    x[-1] = 1.0
    fit = fit_mode_shape(x, 7.0 * polynomial(c, x))
    assert np.allclose(fit.coefficients, c, atol=1e-9)
    assert fit.residual < 1e-10


def test_bad_shapes_are_refused():
    x = np.linspace(0.0, 1.0, 4)
    with pytest.raises(ValueError, match="at least 5"):
        fit_mode_shape(x, x**2)
    x = np.linspace(0.0, 1.0, 10)
    with pytest.raises(ValueError, match="tip deflection"):
        fit_mode_shape(x, np.sin(np.pi * x))


def test_modes_chosen_by_family_and_frequency():
    part = [{"axial": 0, "in-plane": 0.1, "out-of-plane": 0.9, "torsion": 0},
            {"axial": 0, "in-plane": 0.8, "out-of-plane": 0.2, "torsion": 0},
            {"axial": 0, "in-plane": 0.0, "out-of-plane": 0.1, "torsion": 0.9},
            {"axial": 0, "in-plane": 0.0, "out-of-plane": 1.0, "torsion": 0}]
    chosen = choose_modes(part, [10.0, 20.0, 25.0, 30.0])
    assert chosen == {"BldFl1Sh": 0, "BldFl2Sh": 3, "BldEdgSh": 1}
    assert "BldFl2Sh" not in choose_modes(part[:3], [10.0, 20.0, 25.0])


def test_section_layout(tmp_path):
    x = np.linspace(0.0, 1.0, 21)
    fits = [fit_mode_shape(x, cantilever_mode(1 + (stem == "BldFl2Sh"), x), name=stem)
            for stem, *_ in SHAPES]
    text = elastodyn_section(fits, "fitted by fxflex")
    lines = text.splitlines()
    assert lines[0].startswith("---") and "BLADE MODE SHAPES" in lines[0]
    values = [ln for ln in lines if "coeff of x^" in ln]
    assert len(values) == 15
    assert values[0].split()[1] == "BldFl1Sh(2)" and values[-1].split()[1] == "BldEdgSh(6)"
    for stem, *_ in SHAPES:
        got = [float(ln.split()[0]) for ln in values if ln.split()[1].startswith(stem)]
        assert len(got) == len(POWERS) and sum(got) == pytest.approx(1.0, abs=1e-6)
    path = tmp_path / "blade.dat"
    write_elastodyn(str(path), fits)
    assert path.read_text() == elastodyn_section(fits)
    assert [p.name for p in tmp_path.iterdir()] == ["blade.dat"]


def test_missing_shapes_name_the_mode():
    part = [{"axial": 0, "in-plane": 0.1, "out-of-plane": 0.9, "torsion": 0},
            {"axial": 0, "in-plane": 0.8, "out-of-plane": 0.2, "torsion": 0}]
    assert missing_shapes(part, [1.0, 2.0]) == ["flap mode 2 (BldFl2Sh: the 2nd out-of-plane "
                                                "mode)"]
    assert missing_shapes(part + [part[0]], [1.0, 2.0, 3.0]) == []


def _fake_modes(labels):
    """Modes with the given labels (participation 1 in that family) and nothing else."""
    k = len(labels)
    fractions = np.array([[float(f == lab) for f in FAMILIES] for lab in labels])
    shapes = Shapes(x=np.linspace(0, 1, 6), u=np.zeros((k, 6, 3)), theta_x=np.zeros((k, 6)),
                    imag_ratio=np.zeros(k), fractions=fractions)
    lam = -0.1 + 1j * np.arange(1.0, k + 1.0)
    return Modes(rpm=0.0, eigenvalues=lam, tip=np.zeros((6, k)), labels=list(labels),
                 stable=True, shapes=shapes)


def test_export_raises_the_mode_count_until_flap_2_is_found():
    # a model whose 2nd out-of-plane mode is the 9th: torsion and in-plane modes come first
    order = ["out-of-plane", "in-plane"] + ["torsion"] * 6 + ["out-of-plane"] + ["axial"] * 40
    asked = []

    def compute(n):
        asked.append(n)
        return _fake_modes(order[:n])

    modes = modes_for_export(compute, 2, True)
    assert asked == [EXPORT_PAIRS, 2 * EXPORT_PAIRS] and len(modes.labels) == 2 * EXPORT_PAIRS
    asked.clear()
    assert len(modes_for_export(compute, 2, False).labels) == 2 and asked == [2]
    asked.clear()
    # a model with fewer modes than asked has no more to give: one solve, then the refusal
    modes_for_export(lambda n: compute(min(n, 4)), 2, True)
    assert asked == [4]


# -- through the command line -------------------------------------------------------------------

def fx(*args, cwd=None):
    return subprocess.run([*FXFLEX, *args], capture_output=True, text=True, cwd=cwd)


def _uniform(*args):
    sets = [a for item in UNIFORM for a in ("--set", item)]
    return ("modes", "--method", "lebb", *sets, *args)


def _file_coefficients(path) -> dict[str, list[float]]:
    rows = [ln.split() for ln in path.read_text().splitlines() if "coeff of x^" in ln]
    out = {}
    for stem, *_ in SHAPES:
        out[stem] = [float(r[0]) for r in rows if r[1].startswith(stem + "(")]
    return out


@pytest.mark.serial
def test_cli_export_of_the_uniform_cantilever(tmp_path):
    path = tmp_path / "blade.dat"
    r = fx(*_uniform("--n", "2", "--elastodyn", str(path), "--json"))
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    ed = d["elastodyn"]
    assert ed["file"] == str(path) and ed["rpm"] == 0.0
    # --n 2 is raised so that flap 2 is among the modes; every mode computed is reported
    assert d["n"] == len(d["labels"]) >= EXPORT_PAIRS
    in_file = _file_coefficients(path)
    for stem, _, family, ordinal, component in SHAPES:
        shape = ed["shapes"][stem]
        c = np.array(shape["coefficients"])
        size = np.sum(np.abs(c))
        # the constraint, to the KKT solve's round-off (its matrix has entries <= 1)
        assert abs(np.sum(c) - 1.0) <= 1e-12 * size
        # the file prints 8 significant digits: each value to half a unit of the last one
        np.testing.assert_allclose(in_file[stem], c, rtol=5.1e-8, atol=0)
        assert abs(sum(in_file[stem]) - 1.0) <= 5.1e-8 * size
        j = shape["mode"] - 1
        assert d["labels"][j] == family and shape["component"] == "XYZ"[component]
        assert [lab for lab in d["labels"][:j + 1]].count(family) == ordinal
        assert shape["frequency_hz"] == d["frequencies_hz"][j]


def _conditioning(xi, weight, c):
    """(singular values of the weighted powers matrix, the round-off of two KKT solves of the
    fit on the polynomial's values: normal equations, so eps cond^2 on the coefficients, and
    |xi^k| <= 1)."""
    A = np.stack([xi**k for k in POWERS], axis=1) * np.sqrt(weight / np.sum(weight))[:, None]
    sv = np.linalg.svd(A, compute_uv=False)
    return sv, 2 * np.finfo(float).eps * (sv[0] / sv[-1]) ** 2 * np.sum(np.abs(c))


@pytest.mark.serial
@pytest.mark.parametrize("n, stem", [(1, "BldFl1Sh"), (2, "BldFl2Sh")])
def test_cli_fit_matches_the_closed_form_fit(tmp_path, n, stem):
    """The fitted flap shapes against the fit of the closed-form Euler-Bernoulli mode at the same
    stations. The fit is the projection onto an affine subspace in the trapezoid-weighted norm,
    so it does not move the shapes apart: ||p - p_exact|| <= e = ||w - w_exact|| (w the LEBB
    shape of the JSON, both at unit tip), its residual is within e of the exact shape's, and the
    coefficients differ by at most e / sigma_min of the weighted powers matrix."""
    r = fx(*_uniform("--elastodyn", str(tmp_path / "b.dat"), "--json"))
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    shape = d["elastodyn"]["shapes"][stem]
    x = np.array(d["shapes"]["x"])
    xi = x / x[-1]
    w = np.array(d["shapes"]["modes"][shape["mode"] - 1]["u"])[:, 2]
    w = w / w[-1]
    exact = cantilever_mode(n, xi)
    exact = exact / exact[-1]
    weight = trapezoid_weights(xi)
    norm = lambda v: np.sqrt(np.sum(weight * v**2) / np.sum(weight))     # noqa: E731
    e = norm(w - exact)
    ref = fit_mode_shape(x, exact)
    c = np.array(shape["coefficients"])
    sv, slack = _conditioning(xi, weight, c)
    assert norm(polynomial(c, xi) - polynomial(ref.coefficients, xi)) <= e + slack
    assert abs(shape["residual"] - ref.residual) <= e + slack
    assert np.linalg.norm(c - ref.coefficients) <= (e + slack) / sv[-1]
    # and the fit is good: the polynomial's own error for mode 1 (test above), and LEBB's
    # 10 Hermite elements give the shape to better than that
    if n == 1:
        assert shape["residual"] < 1e-5 and e < 1e-4


@pytest.mark.serial
def test_cli_without_export_reports_null(tmp_path):
    r = fx(*_uniform("--n", "2", "--json"))
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["elastodyn"] is None and d["n"] == 2


@pytest.mark.serial
def test_cli_refusals_write_nothing(tmp_path):
    path = tmp_path / "blade.dat"
    scene = tmp_path / "s.toml"
    scene.write_text("[rotation]\nrpm = 0.0\n")
    (tmp_path / "m").mkdir()
    cases = {
        "campbell": (["--campbell", "0:1000:2", "--elastodyn", str(path)], "--campbell"),
        "folder": (["--elastodyn", str(tmp_path)], "is a directory"),
        "no folder": (["--elastodyn", str(tmp_path / "nope" / "b.dat")], "does not exist"),
        "scene": (["--scene", str(scene), "--elastodyn", str(scene)], "--scene"),
        "out": (["--out", str(tmp_path / "m"), "--elastodyn",
                 str(tmp_path / "m" / "modes_lebb.json")], "--out"),
        "stations": (["--set", "mesh.beam_elements=3", "--elastodyn", str(path)], "at least 5"),
        "device": (["--elastodyn", "/dev/full"], "not a regular file"),
        "link": (["--scene", str(scene), "--elastodyn", str(tmp_path / "link.dat")], "--scene"),
    }
    (tmp_path / "link.dat").symlink_to("s.toml")
    for name, (args, needle) in cases.items():
        r = fx(*_uniform(*args))
        lines = r.stderr.strip().splitlines()
        assert r.returncode == 2, (name, r.stderr)
        assert len(lines) == 1 and "--elastodyn" in lines[0] and needle in lines[0], name
        assert r.stdout == "", name
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.dat", "m", "s.toml"]
    assert list((tmp_path / "m").iterdir()) == []
    assert scene.read_text() == "[rotation]\nrpm = 0.0\n"


#: small meshes for every method (the solids' shapes come from their node layers)
SMALL = {"lebb": [], "nebb": ["mesh.beam_variant=\"locking-free\""],
         "ancf": ["mesh.beam_variant=\"locking-free\""],
         "tlf": ["mesh.solid=[10,2,2]", "mesh.solid_degree=2"],
         "ffrf": ["mesh.solid=[10,2,2]", "mesh.solid_degree=2"],
         "gcms": ["mesh.solid=[10,2,2]", "mesh.solid_degree=2", "reduction.gcms_modes=30"]}


@pytest.mark.parametrize("method", list(SMALL))
def test_export_of_every_method_against_the_closed_form(method):
    """The export's modes and fits on the uniform cantilever at rest, every method: flap 1 and 2
    are the 1st and 2nd out-of-plane modes, and each flap fit lies within e = ||w - w_exact||
    (the method's shape error at its stations, weighted RMS at unit tip) of the closed-form
    mode's fit (the fit is an affine projection in that norm: it does not move shapes apart)."""
    from mpi4py import MPI

    from fxflex.analysis.modes import elastodyn_export, modes_of
    from fxflex.formulation import build
    from fxflex.scene import load_scene

    scene = load_scene(overrides=UNIFORM + SMALL[method])
    modes = modes_for_export(lambda n: modes_of(build(method, scene, MPI.COMM_WORLD), n), 2,
                             True)
    fits, member, _ = elastodyn_export(modes, scene, "unused.dat")
    sh = modes.shapes
    xi = sh.x / scene.geometry.length
    weight = trapezoid_weights(xi)
    norm = lambda v: np.sqrt(np.sum(weight * v**2) / np.sum(weight))     # noqa: E731
    flaps = [j for j, lab in enumerate(modes.labels) if lab == "out-of-plane"]
    for n, fit in ((1, fits[0]), (2, fits[1])):
        assert fit.mode - 1 == flaps[n - 1] and np.sum(fit.coefficients) == pytest.approx(1.0)
        w = sh.u[fit.mode - 1, :, 2] / sh.u[fit.mode - 1, -1, 2]
        exact = cantilever_mode(n, xi) / cantilever_mode(n, np.array([1.0]))[0]
        e = norm(w - exact)
        ref = fit_mode_shape(sh.x, exact, length=scene.geometry.length)
        slack = _conditioning(xi, weight, fit.coefficients)[1]
        assert norm(polynomial(fit.coefficients, xi) - polynomial(ref.coefficients, xi)) \
            <= e + slack
        assert fit.residual <= ref.residual + e + slack
    assert member["shapes"]["BldEdgSh"]["family"] == "in-plane"
    assert modes.labels[fits[2].mode - 1] == "in-plane"
