"""Output: JSON results (SPEC section 8), CSV time series written as the run goes, progress."""

from fxflex.io.progress import Progress
from fxflex.io.payload import envelope, tip_mm
from fxflex.io.series import SeriesWriter

__all__ = ["Progress", "SeriesWriter", "envelope", "tip_mm"]
