"""fxflex bench pybmodes (issue 16): fxflex's beams beside the peer code pyBModes on a uniform
rotating cantilever (docs/pybmodes.md). Each gap is explained by a law with a known size, so
each check is sharp: the input written for pyBModes (its Euler-Bernoulli closed form), the
rotary inertia fxflex carries and pyBModes does not, the torsion element's error, and the two
torsion laws under rotation."""

import math

import pytest
from mpi4py import MPI

pytest.importorskip("pybmodes", reason="pyBModes (peer code) not installed: ./dev setup does")

from fxflex.bench import peers  # noqa: E402
from fxflex.scene import Scene  # noqa: E402

#: the beams and pyBModes are replicated, nothing is distributed: serial only
pytestmark = pytest.mark.serial

BASE = Scene()
N = peers.ELEMENTS
#: pyBModes' own discretisation error at 40 cubic elements: its lowest six frequencies change by
#: less than 2e-6 from 20 to 40 elements (docs/pybmodes.md)
PEER_ERROR = 2e-6


def _both(length: float, rpm: float, elements: int, tmp_path, methods=("lebb",)):
    case = peers.uniform_scene(BASE, length, rpm, elements)
    path = peers.write_inputs(case, str(tmp_path), f"L{length:g}_{rpm:g}")
    peer = peers._ordinals(peers.pybmodes_frequencies(path, elements, peers.section_row(case)))
    ours = {m: peers._ordinals(peers.fxflex_frequencies(m, case)) for m in methods}
    return case, peer, ours


@pytest.fixture(scope="module")
def at_rest(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("pybmodes")
    return {L: _both(L, 0.0, int(N * L), tmp) for L in (1.0, 3.0)}


def test_the_peer_input_is_the_euler_bernoulli_cantilever(at_rest):
    """pyBModes on the written deck: flap 1 and edge 1 are 1.8751^2 / (2 pi) sqrt(EI / (rho A
    L^4)) of the scene's root rectangle, to pyBModes' discretisation error."""
    case, peer, _ = at_rest[1.0]
    row = peers.section_row(case)
    beta = 1.8751040687119611
    for family, stiffness in (("flap", "flp_stff"), ("edge", "edge_stff")):
        closed = beta ** 2 / (2 * math.pi) * math.sqrt(row[stiffness] / row["mass_den"])
        assert peer[(family, 1)] == pytest.approx(closed, rel=2 * PEER_ERROR), family


def test_bending_gaps_at_rest_are_the_rotary_inertia(at_rest):
    """fxflex's beams carry rho I in the mass, pyBModes' bending does not: the Rayleigh beam's
    shift is proportional to the radius of gyration squared over L^2, so edge / flap = I_z / I_y
    = (b / h)^2 and 3 m / 1 m = 1 / 9 -- to the beams' discretisation error (at most 5e-5 of the
    frequency at 40 elements per metre, a few per cent of the 7e-4..3e-3 gaps)."""
    gap = {L: {f: at_rest[L][2]["lebb"][(f, 1)] / at_rest[L][1][(f, 1)] - 1.0
               for f in ("flap", "edge")} for L in at_rest}
    g = BASE.geometry
    assert gap[1.0]["flap"] < 0 and gap[1.0]["edge"] < 0
    assert gap[1.0]["edge"] / gap[1.0]["flap"] == pytest.approx((g.root_y / g.root_z) ** 2,
                                                                rel=0.05)
    assert gap[3.0]["edge"] / gap[1.0]["edge"] == pytest.approx(1.0 / 9.0, rel=0.05)


def test_torsion_at_rest_differs_by_the_linear_elements_error(at_rest):
    """Both sides have the same G J and rho I_p; fxflex's torsion is linear Lagrange, whose
    first fixed-free frequency is high by (k h)^2 / 24 (k = pi / 2L, h = L / n), next terms
    (k h)^4: the gap is that, to pyBModes' error."""
    _, peer, ours = at_rest[1.0]
    kh = math.pi / 2 / N
    assert ours["lebb"][("torsion", 1)] / peer[("torsion", 1)] - 1.0 == pytest.approx(
        kh ** 2 / 24, abs=5 * PEER_ERROR)


def test_torsion_under_rotation_two_laws(at_rest, tmp_path):
    """At 10000 rpm: pyBModes and NEBB carry the propeller moment, omega^2 = omega_0^2 + Omega^2
    (I_yy - I_zz) / I_p (section mass moments; NEBB through the second-order rotation of its
    sections, docs/beams.md); LEBB's linear rotation field keeps only the spin softening,
    omega^2 = omega_0^2 - Omega^2 I_zz / I_p (docs/pybmodes.md). pyBModes to its error (it uses
    the undeformed tension); NEBB and LEBB to twice the root axial strain rho Omega^2 L^2 / (2E),
    the size of the stretched state's other changes."""
    rpm = 10000.0
    case, peer, ours = _both(1.0, rpm, N, tmp_path, methods=("nebb", "lebb"))
    rest_peer = at_rest[1.0][1][("torsion", 1)]
    _, _, rest = _both(1.0, 0.0, N, tmp_path, methods=("nebb", "lebb"))
    g, m = case.geometry, case.material
    Iyy, Izz = g.root_z * g.root_y ** 3 / 12, g.root_y * g.root_z ** 3 / 12   # about Z, Y
    Omega2 = (rpm * math.pi / 30) ** 2
    shift = lambda f, f0: (2 * math.pi) ** 2 * (f ** 2 - f0 ** 2) / Omega2
    assert shift(peer[("torsion", 1)], rest_peer) == pytest.approx(
        (Iyy - Izz) / (Iyy + Izz), rel=1e-3)
    strain = m.rho * Omega2 * g.length ** 2 / (2 * m.E)
    assert shift(ours["nebb"][("torsion", 1)], rest["nebb"][("torsion", 1)]) == pytest.approx(
        (Iyy - Izz) / (Iyy + Izz), rel=2 * strain)
    assert shift(ours["lebb"][("torsion", 1)], rest["lebb"][("torsion", 1)]) == pytest.approx(
        -Izz / (Iyy + Izz), rel=2 * strain)


def test_bench_writes_its_table(tmp_path):
    res = peers.run(BASE, str(tmp_path), MPI.COMM_WORLD, quick=True)
    families = {(r["family"], r["ordinal"]) for r in res["rows"]}
    assert {("flap", 1), ("edge", 1), ("torsion", 1), ("axial", 1)} <= families
    assert (tmp_path / "pybmodes.md").read_text().count("| 1 | 1000 |") >= 5
    assert (tmp_path / "inputs" / "L1_rpm1000.bmi").is_file()
