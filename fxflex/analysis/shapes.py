"""Mode shapes along the span and their kinetic-energy participation (SPEC section 10).

Every formulation's ``mode_span(X)`` gives, at span stations x (m from the root: the beam nodes,
the solids' node layers), the section-rigid motion of each (complex) mode: the translation
u = (u_X, u_Y, u_Z) of the section centroid and the section rotation theta_X about X, in O-XYZ
(the rotating frame). From them, with m(x) = rho A(x) the mass per length and
I_p(x) = rho (I_Y(x) + I_Z(x)) the polar mass moment per length about the centroid (the scene's
section, :meth:`fxflex.mesh.geometry.BeamShape.section`; rho b h and rho b h (b^2 + h^2) / 12 for
the paper's rectangle), the kinetic energy of the section-rigid motion, lambda^2 / 2 times

    T = int m (|u_X|^2 + |u_Y|^2 + |u_Z|^2) + I_p |theta_X|^2 dx      (trapezoid rule in x),

splits into four fractions, the **participation**: axial int m |u_X|^2, in-plane int m |u_Y|^2,
out-of-plane int m |u_Z|^2 and torsion int I_p |theta_X|^2, each over T, so they sum to 1. They
do not depend on the mode's complex scale. The section's warping and the bending rotations'
rotary inertia are left out (the motion a beam analyst reads from a mode shape).

The **shape** reported is real: each mode s is turned by the phase phi that maximises
||Re(e^{i phi} s)||, phi = -arg(s^T W s) / 2 in the energy norm ||s||^2 = s^H W s of T (W the
trapezoid weights times m, m, m, I_p), so the part of the mode that is not in phase is as small as
it can be; ``imag_ratio`` = ||Im|| / ||Re|| of the turned mode says how large it stays (0 for a
real mode, 1 for a travelling wave). Then it is scaled so that the largest translation magnitude
|u| over the stations is 1 and the translation component of largest modulus is positive.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["FAMILIES", "Shapes", "span_inertia", "trapezoid_weights", "participation",
           "real_shapes", "mode_shapes", "mac", "write_shapes_csv", "plot_shapes"]

#: the participation families, in the order of the rows of ``mode_span``'s translation and
#: rotation (X, Y, Z, theta_X)
FAMILIES = ("axial", "in-plane", "out-of-plane", "torsion")


@dataclass
class Shapes:
    """Real, normalised mode shapes along the span (module docstring)."""

    x: np.ndarray                   # (s,) stations, m from the root
    u: np.ndarray                   # (k, s, 3) translations X, Y, Z
    theta_x: np.ndarray             # (k, s) rotations about X (rad per unit translation)
    imag_ratio: np.ndarray          # (k,) ||Im|| / ||Re|| after the phase turn
    fractions: np.ndarray           # (k, 4) participation, FAMILIES order

    @property
    def participation(self) -> list[dict[str, float]]:
        return [dict(zip(FAMILIES, map(float, row))) for row in self.fractions]

    @property
    def labels(self) -> list[str]:
        """The family with the largest participation, per mode."""
        return [FAMILIES[i] for i in np.argmax(self.fractions, axis=1)]

    def to_dict(self) -> dict:
        """SPEC section 10's ``shapes``: ``x`` and per mode ``u`` ([X, Y, Z] per station),
        ``theta_x`` and ``imag_ratio``."""
        return {"x": self.x.tolist(),
                "modes": [{"u": u.tolist(), "theta_x": t.tolist(), "imag_ratio": float(r)}
                          for u, t, r in zip(self.u, self.theta_x, self.imag_ratio)]}


def span_inertia(scene, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(m, I_p) at stations x: rho A and rho (I_Y + I_Z) of the scene's section."""
    from fxflex.mesh.geometry import BeamShape

    sec = BeamShape(scene.geometry).section(np.asarray(x, float))
    rho = scene.material.rho
    return rho * np.asarray(sec.A, float), rho * np.asarray(sec.I_Y + sec.I_Z, float)


def trapezoid_weights(x: np.ndarray) -> np.ndarray:
    """w with sum_i w_i f(x_i) the trapezoid rule on the stations x (increasing)."""
    x = np.asarray(x, float)
    w = np.zeros_like(x)
    dx = np.diff(x)
    w[:-1] += 0.5 * dx
    w[1:] += 0.5 * dx
    return w


def _weights(x, m, ip) -> np.ndarray:
    """(4, s): trapezoid weight times m, m, m, I_p."""
    w = trapezoid_weights(x)
    return np.stack([w * m, w * m, w * m, w * ip])


def participation(x, S, m, ip) -> np.ndarray:
    """(k, 4) fractions of the section-rigid kinetic energy of each mode of ``S`` (4, s, k)
    in axial, in-plane, out-of-plane and torsional motion (module docstring)."""
    W = _weights(x, m, ip)
    energy = np.einsum("rs,rsk->kr", W, np.abs(S) ** 2)
    total = energy.sum(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, energy / np.where(total > 0, total, 1.0), np.nan)


def real_shapes(x, S, m, ip) -> tuple[np.ndarray, np.ndarray]:
    """(R (4, s, k) real, imag_ratio (k,)): each mode turned by the phase that maximises its
    real part in the energy norm and scaled to a unit largest translation (module docstring)."""
    W = _weights(x, m, ip)[..., None]
    S = np.asarray(S, dtype=complex)
    phase = np.exp(-0.5j * np.angle(np.sum(W * S * S, axis=(0, 1))))
    T = S * phase
    re = np.sqrt(np.sum(W * T.real ** 2, axis=(0, 1)))
    im = np.sqrt(np.sum(W * T.imag ** 2, axis=(0, 1)))
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(re > 0, im / np.where(re > 0, re, 1.0), np.inf)
    R = T.real
    k = R.shape[2]
    scale = np.ones(k)
    for j in range(k):
        u = R[:3, :, j]
        big = float(np.max(np.linalg.norm(u, axis=0))) if u.size else 0.0
        if big > 0:
            i = np.unravel_index(np.argmax(np.abs(u)), u.shape)
            scale[j] = np.sign(u[i]) / big
    return R * scale, ratio


def mode_shapes(scene, x, S) -> Shapes:
    """:class:`Shapes` of the modes ``S`` (4, s, k) at stations ``x`` of ``scene``'s body."""
    x = np.asarray(x, float)
    m, ip = span_inertia(scene, x)
    R, ratio = real_shapes(x, S, m, ip)
    return Shapes(x=x, u=np.transpose(R[:3], (2, 1, 0)), theta_x=R[3].T, imag_ratio=ratio,
                  fractions=participation(x, S, m, ip))


def mac(a: np.ndarray, b: np.ndarray, weights: np.ndarray | None = None) -> float:
    """|a^H W b|^2 / ((a^H W a) (b^H W b)) for two shapes sampled at the same stations (W
    diagonal, default the identity)."""
    a, b = np.ravel(a), np.ravel(b)
    w = np.ones(a.shape) if weights is None else np.ravel(weights)
    return float(abs(np.sum(w * np.conj(a) * b)) ** 2
                 / (np.sum(w * abs(a) ** 2) * np.sum(w * abs(b) ** 2)))


def write_shapes_csv(shapes: Shapes, path: str) -> None:
    """One row per mode and station: mode (1-based), x, uX, uY, uZ, theta_x."""
    with open(path, "w") as fh:
        fh.write("mode,x,uX,uY,uZ,theta_x\n")
        for j, (u, t) in enumerate(zip(shapes.u, shapes.theta_x)):
            for x, (ux, uy, uz), tx in zip(shapes.x, u, t):
                ux, uy, uz, tx = (v + 0.0 for v in (ux, uy, uz, tx))     # no "-0"
                fh.write(f"{j + 1},{x:.10g},{ux:.10g},{uy:.10g},{uz:.10g},{tx:.10g}\n")


def plot_shapes(shapes: Shapes, path: str, frequencies_hz=None, title: str = "") -> None:
    """PNG (matplotlib Agg): u_Y, u_Z and theta_X of every mode along the span, one panel each,
    a line per mode labelled with its number, frequency and label."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(7.5, 8.0), sharex=True)
    names = ("in-plane translation u_Y", "out-of-plane translation u_Z",
             "rotation about X theta_X (rad)")
    labels = shapes.labels
    for j in range(shapes.u.shape[0]):
        f = "" if frequencies_hz is None else f" {float(frequencies_hz[j]):.4g} Hz"
        lab = f"{j + 1}:{f} {labels[j]}"
        for ax, y in zip(axes, (shapes.u[j, :, 1], shapes.u[j, :, 2], shapes.theta_x[j])):
            ax.plot(shapes.x, y, marker="o", ms=2.5, lw=1.1, label=lab)
    for ax, name in zip(axes, names):
        ax.set_ylabel(name, fontsize=8)
        ax.grid(alpha=0.3)
        ax.axhline(0.0, color="k", lw=0.6)
    axes[-1].set_xlabel("distance from the root x (m)")
    axes[0].legend(fontsize=7, ncol=2, loc="best")
    axes[0].set_title(title or "mode shapes (largest translation 1)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
