"""The beam line: equal elements along X from the root, Gauss points, section properties there.

Element e joins nodes e and e + 1 at distances x_e = e l_e and x_e + l_e from the root (the root
is node 0, the free end node n_el). The section properties (area, moments, torsion constants of the
twisted tapered rectangle, paper Eq. 41) come in closed form from
:class:`fxflex.mesh.geometry.BeamShape` at every Gauss point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fxflex.beam.elements import gauss
from fxflex.mesh.geometry import BeamShape, SectionProperties
from fxflex.scene import Scene

__all__ = ["BeamLine", "beam_line"]


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
