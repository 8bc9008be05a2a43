"""The formulations of ``fxflex compare`` (:mod:`fxflex.analysis.compare`), built once per method
and mass and moved to each speed and damping with ``at``: FFRF and GCMS then share one mesh,
its operators, modes and projections across the studies; the beams rebuild in milliseconds."""

from __future__ import annotations

from fxflex.formulation import BuildOptions, Formulation, build
from fxflex.scene import Scene

__all__ = ["FormCache"]


class FormCache:
    """Formulations of ``base`` at (rpm, c, damping model), per method and ``--mass``.

    Small dense models are kept, one per (method, rpm, c, model, mass), and the first of each
    method and mass is the one the others come from (``at``). A distributed model (TLF,
    ``form.distributed``) is not kept -- one of its builds holds the mesh, the factorised mass
    and the force operators -- and is built afresh each time it is asked for (its mesh is read
    from the cache); the studies ask for it once per run.
    """

    def __init__(self, base: Scene, comm):
        self.base, self.comm = base, comm
        self._forms: dict = {}
        self._first: dict = {}

    def scene(self, rpm: float, c: float, model: str) -> Scene:
        """``base`` at speed ``rpm``, damping coefficient ``c`` and damping model ``model``."""
        return self.base.replace(**{"rotation.rpm": float(rpm), "damping.c": float(c),
                                    "damping.model": model})

    def get(self, method: str, rpm: float, c: float, model: str, mass: str | None = None
            ) -> Formulation:
        """``method`` (with ``--mass`` ``mass``) for the scene at (rpm, c, model)."""
        key = (method, rpm, c, model, mass)
        if key in self._forms:
            return self._forms[key]
        first = self._first.get((method, mass))
        if first is None:
            form = build(method, self.scene(rpm, c, model), self.comm, BuildOptions(mass=mass))
        else:
            form = first.at(rpm=rpm, damping=c, model=model)
        if not form.distributed:
            self._forms[key] = form
            self._first.setdefault((method, mass), form)
        return form
