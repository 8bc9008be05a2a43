"""Mode shapes along the span and their participation (SPEC section 10, issue 16,
fxflex.analysis.shapes): the uniform cantilever at rest against the closed-form Euler-Bernoulli
modes for every beam method and a small Q2 solid, the participation's definition, the phase
turn, the ``--out`` files, and TLF's shapes under MPI equal to one process's."""

import math

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.analysis.modes import modes_of, run_modes
from fxflex.analysis.shapes import (FAMILIES, mac, participation, real_shapes, span_inertia,
                                    trapezoid_weights)
from fxflex.formulation import BuildOptions, build
from fxflex.scene import load_scene

#: a uniform, untwisted, unloaded cantilever at rest, slender (L / h = 50) so that the
#: Euler-Bernoulli modes are what every method converges to (shear and rotary inertia change
#: the third flap shape by O((h / L)^2 (beta L)^2) ~ 1 %, so 1 - MAC by ~1e-4)
UNIFORM = ["geometry.root_y=0.04", "geometry.tip_y=0.04", "geometry.root_z=0.02",
           "geometry.tip_z=0.02", "geometry.twist_deg=0", "rotation.rpm=0", "load.line_load=0"]
#: beta_n L of the first three cantilever bending modes: roots of 1 + cos(bL) cosh(bL) = 0
BETA_L = (1.8751040687, 4.6940911330, 7.8547574382)
CASES = {"lebb": [], "nebb": ["mesh.beam_variant=\"locking-free\""],
         "ancf": ["mesh.beam_variant=\"locking-free\""],
         "tlf": ["mesh.solid=[10,2,2]", "mesh.solid_degree=2"]}


def cantilever(x, length, bl):
    """The clamped-free Euler-Bernoulli mode with beta L = bl at x."""
    b = bl / length
    sigma = (math.cosh(bl) + math.cos(bl)) / (math.sinh(bl) + math.sin(bl))
    return np.cosh(b * x) - np.cos(b * x) - sigma * (np.sinh(b * x) - np.sin(b * x))


def _close_to_one(total):
    # sums of four non-negative fractions, each a ratio of float sums: a few eps
    np.testing.assert_allclose(total, 1.0, rtol=0, atol=1e-12)


@pytest.mark.parametrize("method", sorted(CASES))
def test_uniform_cantilever_flap_shapes_match_the_closed_form(method):
    scene = load_scene(overrides=UNIFORM + CASES[method])
    modes = modes_of(build(method, scene, MPI.COMM_WORLD), 8)
    sh = modes.shapes
    flap = [j for j, lab in enumerate(modes.labels) if lab == "out-of-plane"]
    assert len(flap) >= 3, modes.labels
    w = trapezoid_weights(sh.x)
    for j, bl in zip(flap, BETA_L):
        exact = cantilever(sh.x, scene.geometry.length, bl)
        assert mac(sh.u[j, :, 2], exact, w) >= 0.999, (method, j)
    _close_to_one(sh.fractions.sum(axis=1))
    assert sh.participation[flap[0]]["out-of-plane"] > 0.95
    assert modes.labels[0] == "out-of-plane"
    # the shape is real and normalised: largest translation 1, undamped at rest -> no imag part
    np.testing.assert_allclose(np.max(np.linalg.norm(sh.u, axis=2), axis=1), 1.0, rtol=1e-12)
    assert np.all(sh.imag_ratio < 1e-6)
    d = modes.to_dict()
    assert [set(p) for p in d["participation"]] == [set(FAMILIES)] * len(modes.labels)
    assert len(d["shapes"]["modes"]) == len(modes.labels) and d["shapes"]["x"] == sh.x.tolist()
    first = d["shapes"]["modes"][0]
    assert len(first["u"]) == len(first["theta_x"]) == sh.x.size and len(first["u"][0]) == 3


def test_participation_is_the_section_rigid_kinetic_energy():
    """By hand on three stations: one mode per family, and a mixed one."""
    x = np.array([0.0, 0.5, 1.0])
    m, ip = np.array([2.0, 2.0, 2.0]), np.array([0.5, 0.5, 0.5])
    S = np.zeros((4, 3, 5), dtype=complex)
    for r in range(4):
        S[r, :, r] = [0.0, 1.0, 2.0]
    # mixed: u_Y = 1j x, theta_X = 2 x
    S[1, :, 4], S[3, :, 4] = 1j * x, 2.0 * x
    f = participation(x, S, m, ip)
    np.testing.assert_allclose(f[:4], np.eye(4), atol=0)
    w = trapezoid_weights(x)                         # 0.25, 0.5, 0.25
    ey, et = np.sum(w * m * x**2), np.sum(w * ip * 4 * x**2)
    np.testing.assert_allclose(f[4], [0.0, ey / (ey + et), 0.0, et / (ey + et)], rtol=1e-14)


def test_the_phase_turn_maximises_the_real_part():
    x = np.linspace(0.0, 1.0, 11)
    m, ip = np.ones(11), np.full(11, 1e-3)
    real = np.zeros((4, 11, 2))
    real[2, :, 0] = x**2
    real[1, :, 1] = x
    # a real shape under an arbitrary complex factor: turned back, no imaginary part left
    S = real.astype(complex)
    S[..., 0] *= 3.0 * np.exp(0.7j)
    # a travelling wave: u_Y and u_Z in quadrature, equal energies -> ||Im|| = ||Re||
    S[2, :, 1] = 1j * x
    R, ratio = real_shapes(x, S, m, ip)
    assert ratio[0] < 1e-14 and abs(ratio[1] - 1.0) < 1e-12
    np.testing.assert_allclose(R[..., 0], real[..., 0] / np.max(real[2, :, 0]), atol=1e-14)
    # no other phase gives a larger real part than the one chosen
    W = np.stack([trapezoid_weights(x) * m] * 3 + [trapezoid_weights(x) * ip])
    norm = lambda v: np.sum(W * v.real**2)
    turned = S[..., 1] * np.exp(-0.5j * np.angle(np.sum(W * S[..., 1] ** 2)))
    assert all(norm(turned) >= norm(S[..., 1] * np.exp(1j * p)) - 1e-14
               for p in np.linspace(0, np.pi, 37))


def test_span_inertia_of_the_rectangle():
    scene = load_scene()
    x = np.array([0.0, 1.0])
    m, ip = span_inertia(scene, x)
    g, rho = scene.geometry, scene.material.rho
    b, h = np.array([g.root_y, g.tip_y]), np.array([g.root_z, g.tip_z])
    np.testing.assert_allclose(m, rho * b * h, rtol=1e-14)
    np.testing.assert_allclose(ip, rho * b * h * (b**2 + h**2) / 12.0, rtol=1e-14)


def test_the_span_meets_the_tip_probe_on_the_rotating_default_blade():
    """mode_span's last station is the tip section: the same translation as mode_tip (the
    beams' free-end node exactly)."""
    scene = load_scene(overrides=["rotation.rpm=3000"])
    for method in ("lebb", "ancf"):
        form = build(method, scene, MPI.COMM_SELF)
        _, X = form.rotating_modes(4)
        x, S = form.mode_span(X)
        assert x[0] == 0.0 and math.isclose(x[-1], scene.geometry.length)
        np.testing.assert_allclose(S[:, -1], form.mode_tip(X)[:4], rtol=1e-14, atol=0)
        np.testing.assert_array_equal(S[:, 0], 0.0)


def test_modes_out_writes_the_shapes(tmp_path):
    scene = load_scene(overrides=UNIFORM)
    out = tmp_path / "m"
    payload, text = run_modes("lebb", scene, MPI.COMM_SELF, BuildOptions(), 4, None, str(out))
    rows = (out / "shapes_lebb.csv").read_text().splitlines()
    assert rows[0] == "mode,x,uX,uY,uZ,theta_x"
    x = payload["shapes"]["x"]
    assert len(rows) == 1 + 4 * len(x)
    last = rows[len(x)].split(",")                      # mode 1 at the tip
    assert int(last[0]) == 1 and float(last[1]) == x[-1]
    assert float(last[4]) == payload["shapes"]["modes"][0]["u"][-1][2]
    assert (out / "shapes_lebb.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "shapes_lebb.csv" in text and payload["labels"][0] == "out-of-plane"


@pytest.mark.mpi
def test_tlf_shapes_two_ranks_match_one_process():
    scene = load_scene(overrides=["mesh.solid=[8,2,2]", "rotation.rpm=3000"])
    world = modes_of(build("tlf", scene, MPI.COMM_WORLD), 4).shapes
    alone = modes_of(build("tlf", scene, MPI.COMM_SELF), 4).shapes
    np.testing.assert_array_equal(world.x, alone.x)
    # the eigenvectors converge to pep_eigen's tolerance (~1e-8 relative): shapes to 1e-6
    np.testing.assert_allclose(world.u, alone.u, atol=1e-6)
    np.testing.assert_allclose(world.fractions, alone.fractions, atol=1e-6)
    mine = (world.u.tobytes(), world.labels)
    assert all(other == mine for other in MPI.COMM_WORLD.allgather(mine))
