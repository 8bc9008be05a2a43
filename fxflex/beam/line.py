"""The beam line: equal elements along X from the root, Gauss points, section properties there.

Element e joins nodes e and e + 1 at distances x_e = e l_e and x_e + l_e from the root (the root
is node 0, the free end node n_el). The section properties (area, moments, torsion constants of the
twisted tapered rectangle, paper Eq. 41) come in closed form from
:class:`fxflex.mesh.geometry.BeamShape` at every Gauss point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fxflex.beam.elements import gauss
from fxflex.errors import SceneError
from fxflex.mesh.geometry import BeamShape, SectionProperties
from fxflex.scene import Scene
from fxflex.scene.load import MAX_TWIST_PER_ELEMENT_DEG

__all__ = ["BeamLine", "beam_line", "twist_check", "TWIST_ERROR", "WARN_TWIST_PER_ELEMENT_DEG"]

#: relative error of the tip deflection against the twist dtheta (rad) between an element's
#: ends, e ~ a dtheta^4: the measured 4th-order convergence of docs/robustness.md (LEBB and NEBB,
#: twist_deg 180 to 1440, 1 to 48 elements against 320; the untwisted beam's own error is below
#: 5e-5 from 4 elements on, so the twist is what the elements must resolve); an upper bound from
#: 45 deg per element down, 1.6x above the measured 4.5 % at 90 deg
TWIST_ERROR = {"lebb": 0.0122, "nebb": 0.0122}
#: twist per element (deg) above which the estimated error is given as a warning (about 1e-3)
WARN_TWIST_PER_ELEMENT_DEG = 30.0


@dataclass(frozen=True)
class BeamLine:
    n_el: int
    le: float
    length: float
    hub_radius: float
    x_nodes: np.ndarray          # (n_el + 1,) distance of each node from the root
    xi: np.ndarray               # (nq,) Gauss points on [0, 1]
    w: np.ndarray                # (nq,) weights on [0, 1]
    xq: np.ndarray               # (n_el, nq) distance of each Gauss point from the root
    dx: np.ndarray               # (n_el, nq) weight x element length
    sec: SectionProperties       # arrays (n_el, nq)
    shape: BeamShape

    @property
    def n_nodes(self) -> int:
        return self.n_el + 1


def beam_line(scene: Scene, nq: int) -> BeamLine:
    """Discretise the scene's beam into ``mesh.beam_elements`` equal elements, nq Gauss points
    each."""
    g = scene.geometry
    n_el = scene.mesh.beam_elements
    le = g.length / n_el
    xi, w = gauss(nq)
    x_nodes = le * np.arange(n_el + 1)
    xq = x_nodes[:-1, None] + le * xi[None, :]
    shape = BeamShape(g)
    return BeamLine(n_el=n_el, le=le, length=g.length, hub_radius=g.hub_radius, x_nodes=x_nodes,
                    xi=xi, w=w, xq=xq, dx=np.broadcast_to(le * w, xq.shape).copy(),
                    sec=shape.section(xq), shape=shape)


def twist_check(scene: Scene, method: str) -> list[str]:
    """The solid's limit for the beams: refuse more than MAX_TWIST_PER_ELEMENT_DEG (90 deg) of
    twist between an element's ends, where the tip deflection is off by 4 % or more (30 % at
    180 deg, 720 deg on 4 elements); above WARN_TWIST_PER_ELEMENT_DEG, one warning with the
    estimated error TWIST_ERROR[method] dtheta^4 and the element count that brings it to 1e-3."""
    twist = abs(scene.geometry.twist_deg)
    n_el = scene.mesh.beam_elements
    per = twist / n_el
    what = f"{n_el} {method.upper()} elements twist by {per:g} deg each (geometry.twist_deg = " \
           f"{scene.geometry.twist_deg!r})"
    if per > MAX_TWIST_PER_ELEMENT_DEG:
        need = math.ceil(twist / MAX_TWIST_PER_ELEMENT_DEG)
        raise SceneError("mesh.beam_elements", f"{what}: beyond {MAX_TWIST_PER_ELEMENT_DEG:g} deg "
                                               f"per element the tip deflection is off by more "
                                               f"than 4 % (30 % at 180 deg); allowed: at least "
                                               f"{need:.6g} elements")
    if per <= WARN_TWIST_PER_ELEMENT_DEG or method not in TWIST_ERROR:
        return []
    error = TWIST_ERROR[method] * math.radians(per) ** 4
    good = math.ceil(twist / WARN_TWIST_PER_ELEMENT_DEG)
    return [f"{what}: the tip deflection is estimated off by up to {100 * error:.2g} % "
            f"({TWIST_ERROR[method]:g} x (twist per element in rad)^4, measured); "
            f"mesh.beam_elements >= {good} keeps it near 0.1 %"]
