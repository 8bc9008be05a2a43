"""ElastoDyn blade mode-shape polynomials (SPEC section 10, ``fxflex modes --elastodyn FILE``).

OpenFAST's ElastoDyn describes a blade's flexibility by three mode shapes, flap 1, flap 2 and
edge 1, each a polynomial in the normalised span xi = x / L,

    phi(xi) = sum_{k=2..6} c_k xi^k,     sum_k c_k = 1,

so phi(0) = phi'(0) = 0 (the clamped root) and phi(1) = 1 (unit tip deflection). The coefficients
are fitted to a computed mode's translation normal to the blade: flap modes to the out-of-plane
translation U_Z, the edge mode to the in-plane U_Y (O-XYZ, the rotating frame of SPEC section 2),
each first scaled to a unit tip value.

The fit is the equality-constrained least-squares problem min ||A c - w||_2 over the stations
subject to 1^T c = 1 (A_ik = xi_i^k), solved through its KKT system. The station weights are the
trapezoid weights of the span, so the fit does not depend on how the stations crowd. The residual
reported is the weighted root mean square of (phi(xi_i) - w_i) over the span (w has a unit tip
value, so it is relative to the tip deflection); what the polynomial cannot represent (a shape
with more curvature changes than a 6th-order polynomial, as a 3rd bending mode) shows there.

:func:`elastodyn_section` lays the 15 coefficients out as the "BLADE MODE SHAPES" section of an
ElastoDyn blade input file, one value per line followed by its keyword and description.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace

import numpy as np

from fxflex.analysis.shapes import Shapes, trapezoid_weights

__all__ = ["POWERS", "SHAPES", "Fit", "fit_mode_shape", "polynomial", "elastodyn_section",
           "write_elastodyn", "choose_modes", "fit_modes", "missing_shapes"]

#: the powers of xi ElastoDyn keeps
POWERS = (2, 3, 4, 5, 6)
#: (ElastoDyn keyword stem, description, participation family, ordinal within it, component)
SHAPES = (("BldFl1Sh", "Flap mode 1", "out-of-plane", 1, 2),
          ("BldFl2Sh", "Flap mode 2", "out-of-plane", 2, 2),
          ("BldEdgSh", "Edge mode 1", "in-plane", 1, 1))


@dataclass(frozen=True)
class Fit:
    """One fitted shape: ``coefficients`` c_2..c_6 (summing to 1) and the weighted RMS residual
    relative to the tip deflection."""

    name: str
    coefficients: np.ndarray
    residual: float
    mode: int | None = None          # the mode it was fitted to, 1-based as in the modes table
    frequency_hz: float | None = None

    def to_dict(self) -> dict:
        return {"name": self.name, "coefficients": self.coefficients.tolist(),
                "residual": self.residual, "mode": self.mode,
                "frequency_hz": self.frequency_hz}


def polynomial(coefficients, xi) -> np.ndarray:
    """phi(xi) = sum_k c_k xi^k for k = 2..6."""
    xi = np.asarray(xi, dtype=float)
    return sum(c * xi**k for c, k in zip(coefficients, POWERS))


def fit_mode_shape(x, w, *, name: str = "", length: float | None = None) -> Fit:
    """The constrained fit of a mode's translation ``w`` at span stations ``x`` (m from the root,
    increasing, the last the tip unless ``length`` says otherwise) -- module docstring. Raises
    ValueError for fewer than 5 stations or a shape with no tip deflection."""
    x = np.asarray(x, dtype=float)
    w = np.asarray(w, dtype=float)
    if x.ndim != 1 or x.shape != w.shape:
        raise ValueError("x and w must be 1-D arrays of the same length")
    if x.size < len(POWERS):
        raise ValueError(f"{x.size} stations: the 6th-order fit needs at least {len(POWERS)}")
    if np.any(np.diff(x) <= 0.0):
        raise ValueError("the stations must increase along the span")
    L = float(length if length is not None else x[-1])
    xi = x / L
    tip = float(np.interp(1.0, xi, w)) if xi[-1] >= 1.0 else float(w[-1])
    if not np.isfinite(tip) or abs(tip) <= 1e-12 * max(float(np.max(np.abs(w))), 1e-300):
        raise ValueError("the shape has no tip deflection to normalise by")
    w = w / tip
    weight = trapezoid_weights(xi)
    A = np.stack([xi**k for k in POWERS], axis=1)
    sq = np.sqrt(weight)[:, None]
    Aw, bw = A * sq, w * sq[:, 0]
    n = len(POWERS)
    kkt = np.zeros((n + 1, n + 1))
    kkt[:n, :n] = Aw.T @ Aw
    kkt[:n, n] = kkt[n, :n] = 1.0
    rhs = np.concatenate([Aw.T @ bw, [1.0]])
    c = np.linalg.solve(kkt, rhs)[:n]
    misfit = A @ c - w
    residual = float(np.sqrt(np.sum(weight * misfit**2) / np.sum(weight)))
    return Fit(name=name, coefficients=c, residual=residual)


def choose_modes(participation: list[dict], frequencies_hz) -> dict[str, int]:
    """For each of flap 1, flap 2, edge 1 (SHAPES) the index of the mode used: the n-th mode, by
    frequency, whose largest kinetic-energy fraction is that family (``participation``, SPEC
    section 10). Shapes with no such mode among those computed are left out."""
    order = np.argsort(np.asarray(frequencies_hz, dtype=float), kind="stable")
    chosen = {}
    for stem, _, family, ordinal, _ in SHAPES:
        hits = [int(i) for i in order
                if max(participation[i], key=participation[i].get) == family]
        if len(hits) >= ordinal:
            chosen[stem] = hits[ordinal - 1]
    return chosen


def missing_shapes(participation: list[dict], frequencies_hz) -> list[str]:
    """The SHAPES (as "flap 2 (BldFl2Sh: the 2nd out-of-plane mode)") that
    :func:`choose_modes` finds no mode for."""
    chosen = choose_modes(participation, frequencies_hz)
    ordinal = {1: "1st", 2: "2nd"}
    return [f"{description.lower()} ({stem}: the {ordinal[n]} {family} mode)"
            for stem, description, family, n, _ in SHAPES if stem not in chosen]


def fit_modes(shapes: Shapes, frequencies_hz, length: float) -> list[Fit]:
    """The three fits of SHAPES to the modes ``shapes`` (:class:`~fxflex.analysis.shapes.Shapes`,
    with their frequencies): flap 1 and 2 to the out-of-plane translation u_Z of the 1st and 2nd
    out-of-plane modes, edge 1 to the in-plane u_Y of the 1st in-plane mode (:func:`choose_modes`),
    x / ``length`` the normalised span. ValueError naming the shapes no mode was found for, or
    why a fit failed."""
    missing = missing_shapes(shapes.participation, frequencies_hz)
    if missing:
        raise ValueError("no mode for " + ", ".join(missing))
    chosen = choose_modes(shapes.participation, frequencies_hz)
    fits = []
    for stem, description, _, _, component in SHAPES:
        j = chosen[stem]
        try:
            fit = fit_mode_shape(shapes.x, shapes.u[j, :, component], name=stem, length=length)
        except ValueError as exc:
            raise ValueError(f"{description.lower()} ({stem}, mode {j + 1}): {exc}") from None
        fits.append(replace(fit, mode=j + 1, frequency_hz=float(frequencies_hz[j])))
    return fits


def elastodyn_section(fits: list[Fit], comment: str = "") -> str:
    """The "BLADE MODE SHAPES" section of an ElastoDyn blade file for flap 1, flap 2 and edge 1
    (in SHAPES order; ``fits`` named by their keyword stems). A ``comment`` goes into the
    section's header line, which ElastoDyn reads as a comment: it reads the section's lines in
    order, so a comment line of its own could be taken for BldFl1Sh(2)."""
    by_name = {f.name: f for f in fits}
    title = f" BLADE MODE SHAPES ({comment}) " if comment else " BLADE MODE SHAPES "
    lines = ["-" * 22 + title + "-" * max(80 - 22 - len(title), 3)]
    for stem, description, _, _, _ in SHAPES:
        fit = by_name[stem]
        for j, (k, c) in enumerate(zip(POWERS, fit.coefficients)):
            text = description if j == 0 else " " * len(description)
            lines.append(f"{c:14.7E}   {stem}({k}) - {text}, coeff of x^{k}")
    return "\n".join(lines) + "\n"


def write_elastodyn(path: str, fits: list[Fit], comment: str = "") -> None:
    """Write :func:`elastodyn_section` to ``path`` whole or not at all (a temporary file in the
    same directory, renamed)."""
    text = elastodyn_section(fits, comment)
    folder = os.path.dirname(os.path.abspath(path))
    tmp = os.path.join(folder, f".{os.path.basename(path)}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w") as fh:
            fh.write(text)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
