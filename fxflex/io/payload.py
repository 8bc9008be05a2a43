"""The JSON envelope every command's result carries (SPEC section 8)."""

from __future__ import annotations

import math

import numpy as np

from fxflex import __version__
from fxflex.scene import Scene

__all__ = ["envelope", "tip_mm", "jsonable", "COMPONENTS"]

COMPONENTS = ("longitudinal", "orthogonal", "load")


def tip_mm(tip) -> dict[str, float | None]:
    """Free-end deflection (m, O-XYZ) as the SPEC's ``tip_mm`` object in millimetres."""
    return {k: (float(v) * 1e3 if math.isfinite(v) else None) for k, v in zip(COMPONENTS, tip)}


def jsonable(obj):
    """Numpy scalars/arrays and non-finite floats made JSON-safe (NaN/inf become null)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def envelope(scene: Scene, **payload) -> dict:
    """``fxflex_version``, ``scene`` and ``scene_hash`` first, then the command's own fields."""
    out = {"fxflex_version": __version__, "scene": scene.to_dict(), "scene_hash": scene.hash}
    out.update(jsonable(payload))
    return out
