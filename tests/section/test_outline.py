"""Outlines of fxflex.section.outline: orientation, the NACA 4-digit shape, and the refusals."""

import numpy as np
import pytest

from fxflex.section.outline import (ellipse, hollow, naca4, naca_digits, polygon, rectangle,
                                    signed_area)

pytestmark = pytest.mark.serial


def test_orientation_and_extent():
    """Outer contours counter-clockwise, holes clockwise, whatever order the user gives."""
    square = [(0, 0), (0, 1), (1, 1), (1, 0)]                  # clockwise as given
    inner = [(0.2, 0.2), (0.8, 0.2), (0.8, 0.8), (0.2, 0.8)]   # counter-clockwise as given
    o = polygon(square, inner)
    assert signed_area(o.outer) == pytest.approx(1.0)
    assert signed_area(o.inner) == pytest.approx(-0.36)
    assert o.extent == pytest.approx((1.0, 1.0))
    assert signed_area(ellipse(2, 1).outer) > 0 and signed_area(rectangle(2, 1).outer) > 0


def test_naca_shape():
    """Chord from the leading edge (y = 0) to the closed trailing edge (y = chord); the symmetric
    section's largest thickness is t chord (to 2e-4) at 30 % of the chord (thickness polynomial's maximum
    at x = 0.2998); the cambered one's mean line peaks at m chord at p chord."""
    o = naca4("0012", 2.0)
    y, z = o.outer[:, 0], o.outer[:, 1]
    assert y.min() == pytest.approx(0.0, abs=1e-12) and y.max() == pytest.approx(2.0)
    # the closed trailing edge's -0.1036 makes the thickness 0.12002 chord
    assert z.max() - z.min() == pytest.approx(0.12 * 2.0, rel=1e-3)
    assert y[np.argmax(z)] == pytest.approx(0.6, abs=0.01)
    assert signed_area(o.outer) > 0
    assert naca_digits("2412") == pytest.approx((0.02, 0.4, 0.12))


@pytest.mark.parametrize("code, what", [("12", "4 digits"), ("00a2", "4 digits"),
                                        ("2400", "thickness"), ("2012", "both zero or both")])
def test_naca_refusals(code, what):
    with pytest.raises(ValueError, match=what):
        naca4(code, 1.0)


@pytest.mark.parametrize("outer, inner, what", [
    ([(0, 0), (1, 0)], None, "at least 3 points"),
    ([(0, 0), (1, 0), (2, 0)], None, "no area"),
    ([(0, 0), (1, 1), (1, 0), (0, 1)], None, "crosses itself"),
    ([(0, 0), (1, 0), (1, 1), (0, 1)], [(0.5, 0.5), (1.5, 0.5), (1.5, 0.8)], "inside"),
])
def test_polygon_refusals(outer, inner, what):
    with pytest.raises(ValueError, match=what):
        polygon(outer, inner)


def test_hollow():
    """The wall is the distance to the outer contour: a 1 x 0.5 rectangle with a 0.1 wall has a
    0.8 x 0.3 hole; a wall thicker than half the smaller size leaves nothing and is refused, as
    is a hole in a hole. An airfoil's thin trailing edge is left solid (one hole, shorter)."""
    o = hollow(rectangle(1.0, 0.5), 0.1)
    assert -signed_area(o.inner) == pytest.approx(0.8 * 0.3)
    with pytest.raises(ValueError, match="leaves no hollow"):
        hollow(rectangle(1.0, 0.5), 0.25)
    with pytest.raises(ValueError, match="again"):
        hollow(o, 0.01)
    with pytest.raises(ValueError, match="above 0"):
        hollow(rectangle(1.0, 0.5), 0.0)
    air = hollow(naca4("0012", 1.0), 0.01)
    assert air.inner[:, 0].max() < 0.97
