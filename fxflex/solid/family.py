"""One solid mesh, its assembled operators and clamped modes, shared by many FFRF / GCMS builds.

Studies over speed, damping or the reduction (the benchmarks, ``fxflex compare``) vary nothing
that the mesh, K_L, M or the clamped modes depend on, so those are computed once here and every
build only projects (:mod:`fxflex.solid.reduction`); builds that differ from an earlier one of the
same method and reduction only in speed or damping do not even project: they are that build's
``at`` (the projections do not depend on the speed or the damping).
"""

from __future__ import annotations

import time

from fxflex.formulation import rescene
from fxflex.scene import Scene, load_scene
from fxflex.solid.cms import ClampedModes, clamped_modes
from fxflex.solid.ffrf import FFRF
from fxflex.solid.gcms import GCMS
from fxflex.solid.model import SolidModel
from fxflex.solid.reduction import MeshData, mesh_data

__all__ = ["ReducedFamily", "SHARED_SECTIONS"]

#: scene sections a :class:`ReducedFamily` may vary without rebuilding mesh, operators or modes
SHARED_SECTIONS = ("rotation", "damping", "reduction")


class ReducedFamily:
    """One mesh with its assembled operators and clamped modes, and every FFRF / GCMS of scenes
    that differ from ``base`` only in speed, damping or reduction (studies over modes, speeds,
    Gram cuts). ``count`` modes are computed once; builds use the first ones they need."""

    def __init__(self, base: Scene, comm, count: int = 60):
        self.base, self.comm = base, comm
        t0 = time.perf_counter()
        self.model = SolidModel(base, comm)
        self.data: MeshData = mesh_data(self.model)
        t1 = time.perf_counter()
        self.modes: ClampedModes = clamped_modes(self.model, count, K=self.data.K, M=self.data.M)
        self.timings = {"mesh_assemble": t1 - t0, "eigenmodes": time.perf_counter() - t1}
        #: the first build per (method, reduction): later speeds and dampings share its
        #: projections through ``at``
        self._first: dict = {}

    def scene(self, *overrides: str) -> Scene:
        for text in overrides:
            section = text.split("=", 1)[0].split(".", 1)[0]
            if section not in SHARED_SECTIONS:
                raise ValueError(f"{text}: a family only varies {', '.join(SHARED_SECTIONS)}")
        return load_scene(overrides=overrides, base=self.base)

    def build(self, method: str, *overrides: str) -> FFRF | GCMS:
        return self.build_scene(method, self.scene(*overrides))

    def build_scene(self, method: str, scene: Scene) -> FFRF | GCMS:
        """``method`` for ``scene``, which may differ from ``base`` only in the shared sections."""
        for sec in scene.to_dict():
            if sec not in SHARED_SECTIONS and getattr(scene, sec) != getattr(self.base, sec):
                raise ValueError(f"scene differs from the family's in [{sec}]; a family only "
                                 f"varies {', '.join(SHARED_SECTIONS)}")
        first = self._first.get((method, scene.reduction))
        if first is not None:
            rot, damp = scene.rotation, scene.damping
            if rescene(first.scene, rpm=rot.rpm, damping=damp.c, model=damp.model) == scene:
                return first.at(rpm=rot.rpm, damping=damp.c, model=damp.model)
        cls = {"ffrf": FFRF, "gcms": GCMS}[method]
        form = cls(scene, self.comm, model=self.model, data=self.data, modes=self.modes)
        self._first.setdefault((method, scene.reduction), form)
        return form
