"""Growth rates: the exponential fit of a sampled amplitude and the principal root of AB2.

A mode growing like exp(r t) has log |a| linear in t, so r is the least-squares slope of log |a|
against t (:func:`growth_fit`). AB2 on y' = lambda y has the characteristic equation
z^2 - (1 + 3/2 h lambda) z + 1/2 h lambda = 0; its larger root |z| is the amplification per step,
ln|z| / h the rate at which the scheme grows the mode (:func:`ab2_root`, NOTES.md).
"""

from __future__ import annotations

import numpy as np

__all__ = ["growth_fit", "ab2_root"]


def growth_fit(t: np.ndarray, amplitude: np.ndarray) -> float:
    """Least-squares slope of log(amplitude) against t (1/s)."""
    return float(np.polyfit(t, np.log(amplitude), 1)[0])


def ab2_root(h_lambda: np.ndarray) -> np.ndarray:
    """|z| of the principal (larger) root of AB2's characteristic equation for y' = lambda y."""
    b = 1.0 + 1.5 * h_lambda
    d = np.sqrt(b * b - 2.0 * h_lambda + 0j)
    return np.maximum(np.abs(0.5 * (b + d)), np.abs(0.5 * (b - d)))
