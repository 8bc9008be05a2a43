"""Shared scenes for the beam tests: small, uniform or default."""

import pytest

from fxflex.scene import Scene

UNIFORM = {"geometry.tip_y": 0.12, "geometry.tip_z": 0.06, "geometry.twist_deg": 0.0}


@pytest.fixture
def uniform() -> Scene:
    """Untwisted prismatic 0.12 x 0.06 beam, at rest, default load."""
    return Scene().replace(**UNIFORM, **{"rotation.rpm": 0.0})


@pytest.fixture
def default() -> Scene:
    return Scene()
