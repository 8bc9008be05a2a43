"""ANCF element arrays as pure functions (paper Sect. 3.3, Eq. 52-57): the reference coordinates,
the Gauss rule on the prism, the reference Jacobian, the Green-strain tensors of the elastic force,
the scalar mass and the line load. No state, no solver: :class:`fxflex.beam.ancf.ANCF` calls them
once when it is built (STYLE habit 3, as :mod:`fxflex.solid.forms` does for the UFL forms).

Element coordinates are ordered (node, slot, component): 2 nodes x SLOTS slots x 3 components,
2 DPN in all; the slots are :data:`fxflex.beam.elements.ANCF_SLOTS` (Eq. 50-51).
"""

from __future__ import annotations

import numpy as np

from fxflex.beam.elements import ANCF_SLOTS, AncfTables, ancf_tables, gauss, hermite, linear
from fxflex.beam.line import beam_line
from fxflex.scene import Scene

__all__ = ["QUADRATURE", "SLOTS", "DPN", "elasticity_matrix", "reference_coordinates",
           "voigt_linear", "voigt_pairs", "prism_quadrature", "section_rule",
           "reference_gradients",
           "elastic_tensors", "centerline_strain", "centerline_pairs", "cartesian_pairs",
           "linear_from_pairs",
           "gram_tensors", "reference_jacobian", "scalar_mass", "assemble_blocks", "line_load"]

#: Gauss points per element: along X~, Y~, Z~ (the paper's 5 x 3 x 3)
QUADRATURE = (5, 3, 3)
#: position-gradient slots per node (Eq. 51, n = 2)
SLOTS = len(ANCF_SLOTS)
#: coordinates per node
DPN = 3 * SLOTS


def elasticity_matrix(scene: Scene) -> np.ndarray:
    """6 x 6 matrix of moduli, Voigt order xx yy zz xy yz zx, engineering shears.

    ``mesh.beam_variant = "paper"``: isotropic St.Venant-Kirchhoff (lambda, mu). ``"locking-free"``:
    the normal strains uncoupled, each with Young's modulus (sigma_XX = E eps_XX as in beam
    theory, no Poisson coupling between the axial and the transverse normal strains), the shears
    with the material's G = mu: Sopanen and Mikkola's nu = 0 for the normal block, keeping the
    true shear modulus for torsion and shear (docs/beams.md, "Locking-free variants")."""
    lam, mu = scene.material.lame
    C = np.zeros((6, 6))
    if scene.mesh.beam_variant == "paper":
        C[:3, :3] = lam
        C[:3, :3] += 2 * mu * np.eye(3)
    else:
        C[:3, :3] = scene.material.E * np.eye(3)
    C[3:, 3:] = mu * np.eye(3)
    return C


def reference_coordinates(scene: Scene) -> np.ndarray:
    """e0: (n_nodes, 7, 3) reference nodal coordinates of the tapered twisted beam."""
    line = beam_line(scene, 1)
    g = scene.geometry
    b, h, th = line.shape.sizes(line.x_nodes)
    b0, h0, _ = line.shape.sizes(0.0)           # the prism's section is the root's
    e0 = np.zeros((line.n_nodes, SLOTS, 3))
    e0[:, 0, 0] = g.hub_radius + line.x_nodes
    e0[:, 1, 0] = 1.0
    e0[:, 2, 1], e0[:, 2, 2] = b / b0 * np.cos(th), b / b0 * np.sin(th)
    e0[:, 3, 1], e0[:, 3, 2] = -h / h0 * np.sin(th), h / h0 * np.cos(th)
    return e0


def voigt_linear(nx: np.ndarray) -> np.ndarray:
    """B_L (..., 6, 3m): linear Green strain per coordinate (slot a, component i), Eq. 30."""
    shape = nx.shape[:-2]
    m = nx.shape[-2]
    B = np.zeros(shape + (6, m, 3))
    for i in range(3):
        B[..., i, :, i] = nx[..., i]
    for v, (j, k) in zip((3, 4, 5), ((0, 1), (1, 2), (2, 0))):
        B[..., v, :, j] = nx[..., k]
        B[..., v, :, k] = nx[..., j]
    return B.reshape(shape + (6, 3 * m))


def voigt_pairs(nx: np.ndarray) -> np.ndarray:
    """w_ab (..., 6, m, m): the Green strain of a unit Gram entry P_ab (times 2 on the normal
    components), so that eps_N = 1/2 sum_ab P_ab w_ab."""
    out = [np.einsum("...a,...b->...ab", nx[..., i], nx[..., i]) for i in range(3)]
    for j, k in ((0, 1), (1, 2), (2, 0)):
        out.append(np.einsum("...a,...b->...ab", nx[..., j], nx[..., k])
                   + np.einsum("...a,...b->...ab", nx[..., k], nx[..., j]))
    return np.stack(out, axis=-3)


def prism_quadrature(scene: Scene, le: float
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(X~, Y~, Z~, w): the tensor Gauss rule of QUADRATURE on one element's straight prism
    [0, le] x [-b0/2, b0/2] x [-h0/2, h0/2] (b0, h0 the root sizes), X~ slowest. For a section
    other than the paper's rectangle the prism is [0, le] x the root section about its centroid,
    with :func:`section_rule` across it."""
    g = scene.geometry
    if not g.paper_shape:
        xa, wa = gauss(QUADRATURE[0])
        ys, zs, ws = section_rule(scene)
        X = np.repeat(xa, len(ws))
        Y, Z = np.tile(ys, len(xa)), np.tile(zs, len(xa))
        return X, Y, Z, np.einsum("a,b->ab", wa * le, ws).ravel()
    (xa, wa), (yb, wb), (zc, wc) = (gauss(n) for n in QUADRATURE)
    yb, zc = (yb - 0.5) * g.root_y, (zc - 0.5) * g.root_z
    X, Y, Z = (a.ravel() for a in np.meshgrid(xa, yb, zc, indexing="ij"))
    wq = np.einsum("a,b,c->abc", wa * le, wb * g.root_y, wc * g.root_z).ravel()
    return X, Y, Z, wq


#: section rule for other sections: the polynomial degree it integrates exactly, and the Gauss
#: grids on the root section's bounding box whose interior points it may use
SECTION_DEGREE = 8
SECTION_GRIDS = (12, 18, 27, 40)


def section_rule(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Y~, Z~, w): a rule across the root section (about its centroid) with positive weights at
    points inside it, exact for every polynomial of total degree SECTION_DEGREE in Y~, Z~. With
    the quadratic section terms of Eq. 51 the position is quadratic in Y~, Z~, the Green strain
    up to quartic and the energy density up to degree 8 on a straight, untwisted element; the
    mass integrand is of degree 4. (With twist or taper the reference Jacobian makes them
    rational: then the rule, as the paper's 3 x 3 Gauss rule on the rectangle, is an
    approximation.) The weights are the non-negative least-squares fit (a Tchakaloff rule:
    at most 45 points) of the polygon's moments (:func:`fxflex.section.outline.moments`) on the
    interior points of a Gauss grid over the bounding box, refined until the fit is exact to
    1e-10. The paper's rectangle keeps its 3 x 3 Gauss rule."""
    from matplotlib.path import Path
    from scipy.optimize import nnls

    from fxflex.section.blade import Blade
    from fxflex.section.outline import moments

    outline = Blade(scene.geometry).outline(0.0)
    m1 = moments(outline, 1)
    c = np.array([m1[1, 0], m1[0, 1]]) / m1[0, 0]
    d = SECTION_DEGREE
    M = moments(outline, d, origin=c)
    lo, hi = outline.outer.min(axis=0) - c, outline.outer.max(axis=0) - c
    s = 0.5 * (hi - lo)                                  # scaled monomials: a well-posed fit
    pairs = [(i, j) for i in range(d + 1) for j in range(d + 1 - i)]
    rhs = np.array([M[i, j] / (s[0] ** i * s[1] ** j) for i, j in pairs])
    for n in SECTION_GRIDS:
        g, _ = gauss(n)
        Y, Z = (a.ravel() for a in np.meshgrid(lo[0] + (hi[0] - lo[0]) * g,
                                               lo[1] + (hi[1] - lo[1]) * g, indexing="ij"))
        pts = np.column_stack([Y, Z])
        inside = Path(outline.outer - c).contains_points(pts)
        if outline.inner is not None:
            inside &= ~Path(outline.inner - c).contains_points(pts)
        Y, Z = Y[inside], Z[inside]
        V = np.array([(Y / s[0]) ** i * (Z / s[1]) ** j for i, j in pairs])
        w, _ = nnls(V, rhs, maxiter=50 * V.shape[1])
        if np.allclose(V @ w, rhs, rtol=0, atol=1e-10 * abs(rhs[0])):
            keep = w > 0
            return Y[keep], Z[keep], w[keep]
    raise ValueError("section_rule: no positive rule of degree "
                     f"{d} on a {SECTION_GRIDS[-1]}-point grid of the section")


def reference_gradients(e0n: np.ndarray, tab: AncfTables) -> tuple[np.ndarray, np.ndarray]:
    """(det J, nx) per element and Gauss point: J = dx0/dX~ of the reference configuration e0
    (n_nodes, SLOTS, 3), and nx the shape-function gradients with respect to x0 through J^-1
    (Eq. 30 differentiates the strain in the reference configuration)."""
    n_el = e0n.shape[0] - 1
    e0e = np.stack([e0n[:-1], e0n[1:]], axis=1).reshape(n_el, 2 * SLOTS, 3)
    J = np.einsum("eai,qaj->eqij", e0e, tab.dN)
    detJ = np.linalg.det(J)
    nx = np.einsum("qaj,eqji->eqai", tab.dN, np.linalg.inv(J))
    return detJ, nx


def elastic_tensors(C: np.ndarray, nx: np.ndarray, dV: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(K_L^e, T1, T4) per element (Eq. 55, 57) of the continuum Green strain: :func:`gram_tensors`
    with B_L of :func:`voigt_linear` and w of :func:`voigt_pairs`."""
    return gram_tensors(C, voigt_linear(nx), voigt_pairs(nx), dV)


def gram_tensors(C: np.ndarray, BL: np.ndarray, W: np.ndarray, dV: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(K_L^e, T1, T4) per element of a strain eps = B_L u + 1/2 sum_ab w_ab P_ab (Voigt, P the
    Gram matrix of the element slots of u): the linear stiffness int B_L^T C B_L dV, and the
    tensors the invariant engine contracts with the Gram entries, T1 = int (C B_L)^T w dV
    (2 DPN, 2 SLOTS, 2 SLOTS) and T4 = int w^T C w dV (2 SLOTS)^4; dV = det J x Gauss weight.
    BL (n_el, nq, 6, 2 DPN), W (n_el, nq, 6, 2 SLOTS, 2 SLOTS)."""
    n_el, nk = BL.shape[0], BL.shape[-1]
    CBL = np.matmul(C, BL)                                            # (e, q, v, k)
    KLe = np.matmul((BL * dV[..., None, None]).reshape(n_el, -1, nk).transpose(0, 2, 1),
                    CBL.reshape(n_el, -1, nk))
    T1 = np.matmul((CBL * dV[..., None, None]).reshape(n_el, -1, 2 * DPN).transpose(0, 2, 1),
                   W.reshape(n_el, -1, (2 * SLOTS) ** 2)).reshape(n_el, 2 * DPN, 2 * SLOTS,
                                                                2 * SLOTS)
    Wf = W.reshape(n_el, -1, 6, (2 * SLOTS) ** 2)
    CWf = np.matmul(C, Wf * dV[..., None, None])
    T4 = np.matmul(Wf.reshape(n_el, -1, (2 * SLOTS) ** 2).transpose(0, 2, 1),
                   CWf.reshape(n_el, -1, (2 * SLOTS) ** 2)).reshape((n_el,) + (2 * SLOTS,) * 4)
    return KLe, T1, T4


#: element slots of the centerline (r, dr/dX~ of both nodes) and of the first-order section
#: gradients dr/dY~, dr/dZ~ (node 0, node 1)
CENTERLINE, SECTION_Y, SECTION_Z = (0, 1, SLOTS, SLOTS + 1), (2, SLOTS + 2), (3, SLOTS + 3)


def centerline_strain(e0n: np.ndarray, tab: AncfTables, X: np.ndarray, Y: np.ndarray,
                      Z: np.ndarray, le: float) -> tuple[np.ndarray, np.ndarray]:
    """(B_L, w) per element and Gauss point of the locking-free variant's strain (centerline
    curvature, tied shears), for :func:`gram_tensors`: :func:`centerline_pairs` turned to the
    reference axes by :func:`cartesian_pairs`, linearised at e0 by :func:`linear_from_pairs`."""
    W = cartesian_pairs(centerline_pairs(tab, X, Y, Z, le),
                        np.linalg.inv(reference_jacobian(e0n, tab)))
    e0e = np.stack([e0n[:-1], e0n[1:]], axis=1).reshape(len(e0n) - 1, 2 * SLOTS, 3)
    return linear_from_pairs(W, e0e), W


def centerline_pairs(tab: AncfTables, X: np.ndarray, Y: np.ndarray, Z: np.ndarray, le: float
                     ) -> np.ndarray:
    """Wt (nq, 3, 3, 2 SLOTS, 2 SLOTS): the covariant Green strain of the locking-free variant,
    E~_ij = 1/2 sum_ab Wt_ij,ab (e_a . e_b - e0_a . e0_b) on the prism coordinates X~
    (docs/beams.md, "Locking-free variants"). It is the continuum's 1/2 (g_i . g_j - G_i . G_j),
    g_i = dr/dX~_i, with the terms of the centerline r (cubic) and the section gradients r_Y, r_Z
    (linear in X~) changed, each still a combination of Gram entries of the slots:

    - tied transverse shears: gamma_Y = r' . r_Y and gamma_Z = r' . r_Z in g_X . g_Y and
      g_X . g_Z, r' quadratic against a linear r_Y, r_Z (a mismatch that locks), become their
      values at the nodes, where r' is the slot dr/dX~, interpolated linearly (an assumed
      covariant strain of the MITC kind): gamma~ = sum_k L_k(X~) dr/dX~_k . dr/dY~_k;
    - bending: in g_X . g_X the terms 2 Y~ r' . r_Y' and 2 Z~ r' . r_Z' (r_Y', r_Z' constant: a
      curvature constant per element) become 2 Y~ (gamma~_Y' - r'' . r_Y) and the same in Z~,
      by the identity r' . r_Z' = (r' . r_Z)' - r'' . r_Z with the tied shear in place of
      r' . r_Z: the centerline's curvature (linear per element) where the shear vanishes, and a
      Timoshenko curvature (section rotation gradient) at the clamped root, whose section gradients
      are prescribed while dr/dX~ is free.

    tab: :func:`fxflex.beam.elements.ancf_tables` at the points (X, Y, Z) (X = xi in [0, 1])."""
    dN = tab.dN
    Wt = 0.5 * (np.einsum("qai,qbj->qijab", dN, dN) + np.einsum("qaj,qbi->qijab", dN, dN))
    H2 = hermite(X, le, 2)[2]                     # r'' coefficients of the CENTERLINE slots
    L, dL = linear(X, le, 1)
    for j, g, section in ((1, Y, SECTION_Y), (2, Z, SECTION_Z)):
        for n, s in enumerate(section):
            for m, c in enumerate(CENTERLINE):
                own = m == 2 * n + 1          # the pair (dr/dX~, section gradient) of node n
                Wt[:, 0, 0, c, s] = Wt[:, 0, 0, s, c] = g * (own * dL[:, n] - H2[:, m] * L[:, n])
                tied = 0.5 * L[:, n] if own else 0.0
                for i, k in ((0, j), (j, 0)):
                    Wt[:, i, k, c, s] = Wt[:, i, k, s, c] = tied
    return Wt


def cartesian_pairs(Wt: np.ndarray, Jinv: np.ndarray) -> np.ndarray:
    """w (n_el, nq, 6, m, m) in Voigt order (engineering shears) of E = J^-T E~ J^-1, the Green
    strain in the reference configuration's Cartesian axes from the covariant one (Wt of
    :func:`centerline_pairs`, Jinv (n_el, nq, 3, 3) the inverse reference Jacobian)."""
    # J^-T Wt J^-1 per point and slot pair, as two batched matrix products (one three-operand
    # einsum looped over all eight indices at once: 50 ms on 8 elements, now ~3 ms)
    n_el, nq = Jinv.shape[:2]
    m2 = Wt.shape[-1] ** 2
    JT = np.swapaxes(Jinv, -1, -2)                                   # (e, q, l, j)
    half = np.matmul(JT[:, :, None], Wt.reshape(1, nq, 3, 3, m2))    # (e, q, i, l, ab)
    Wc = np.matmul(JT, half.reshape(n_el, nq, 3, 3 * m2)).reshape(
        (n_el, nq, 3, 3) + Wt.shape[-2:])
    out = [Wc[:, :, i, i] for i in range(3)]
    out += [2 * Wc[:, :, j, k] for j, k in ((0, 1), (1, 2), (2, 0))]
    return np.stack(out, axis=2)


def linear_from_pairs(W: np.ndarray, e0e: np.ndarray) -> np.ndarray:
    """B_L (n_el, nq, 6, 3 m) of a strain 1/2 sum_ab w_ab (e_a . e_b - e0_a . e0_b): its derivative
    at e0, sum_a w_ab e0_a on coordinate (b, i); e0e (n_el, m, 3). With it, the strain of a rigid
    motion of e0 is zero to all orders, as the engine's rigid-motion check asks."""
    n_el, nq, nv, m, _ = W.shape
    return np.einsum("eqvab,eai->eqvbi", W, e0e).reshape(n_el, nq, nv, 3 * m)


def reference_jacobian(e0n: np.ndarray, tab: AncfTables) -> np.ndarray:
    """J = dx0/dX~ (n_el, nq, 3, 3) of the reference configuration e0 (n_nodes, SLOTS, 3)."""
    n_el = e0n.shape[0] - 1
    e0e = np.stack([e0n[:-1], e0n[1:]], axis=1).reshape(n_el, 2 * SLOTS, 3)
    return np.einsum("eai,qaj->eqij", e0e, tab.dN)


def scalar_mass(rho: float, dV: np.ndarray, N: np.ndarray) -> np.ndarray:
    """M_s^e = int rho N_a N_b dV per element (Eq. 54, M = M_s (x) I_3):
    (n_el, 2 SLOTS, 2 SLOTS)."""
    n_el, nq = dV.shape[0], N.shape[0]
    return rho * np.einsum("eq,qa,qb->eab", np.broadcast_to(dV, (n_el, nq)), N, N)


def assemble_blocks(Ke: np.ndarray, block: int, n: int) -> np.ndarray:
    """The dense n x n sum of the element matrices Ke (n_el, 2 block, 2 block), element e on the
    rows and columns block e .. block (e + 2) (consecutive elements share a node)."""
    K = np.zeros((n, n))
    for e in range(Ke.shape[0]):
        K[block * e:block * (e + 2), block * e:block * (e + 2)] += Ke[e]
    return K


def line_load(scene: Scene, le: float, n_nodes: int) -> np.ndarray:
    """f = q int N(X~, 0, 0)^T e_z dX~ (the centerline line load, Eq. 43 analogue), assembled:
    (n_nodes * DPN,)."""
    xl, wl = gauss(QUADRATURE[0])
    cl = ancf_tables(xl, np.zeros_like(xl), np.zeros_like(xl), le).N   # (nq, 14)
    fe = scene.load.line_load * le * np.einsum("q,qa->a", wl, cl)
    fq = np.zeros((n_nodes, SLOTS, 3))
    fq[:-1, :, 2] += fe[:SLOTS]
    fq[1:, :, 2] += fe[SLOTS:]
    return fq.reshape(-1)
