"""Reading time series: the mean about which a lightly damped transient oscillates, and the
exponential growth rate of a divergent one."""

from __future__ import annotations

import numpy as np

# growth_fit's old import path kept: it lives in fxflex.numerics.growth
from fxflex.numerics.growth import growth_fit

__all__ = ["hann_mean", "growth_fit"]


def hann_mean(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Hann-weighted mean of the columns of y(t) over the sampled window. An oscillation with n
    cycles in the window leaks about 1/(pi n^3) of its amplitude into it (plain mean: 1/(pi n)),
    so a window of a few periods of the lowest mode suffices."""
    w = 0.5 - 0.5 * np.cos(2 * np.pi * (t - t[0]) / (t[-1] - t[0]))
    y = np.asarray(y, float)
    return (w.reshape((-1,) + (1,) * (y.ndim - 1)) * y).sum(axis=0) / w.sum()
