"""fxflex: dynamics of flexible bodies under large rotation, built on FEniCSx.

Six finite-element formulations of a rotating twisted tapered beam (FFRF, GCMS, TLF, LEBB, NEBB,
ANCF) behind one interface (:class:`fxflex.formulation.Formulation`), one set of integrators and one
output format.

The public Python API (:mod:`fxflex.api`, docs/api.md) is available from the package itself::

    import fxflex
    form = fxflex.build("lebb", fxflex.load_scene(overrides=["rotation.rpm=5000"]))
    print(fxflex.steady(form).tip)              # free-end deflection (m)

Its names are imported on first use (a module-level ``__getattr__``), so that ``import fxflex``
costs nothing and beam-only use never imports dolfinx.
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

#: where each public name lives; imported when first asked for
_LAZY = {**{name: "fxflex.api" for name in (
    "Scene", "load_scene", "scene_from_dict", "SceneError", "FxflexError", "OutputError",
    "METHODS", "PAPER_RPM", "PAPER_DAMPING", "Formulation", "Linearisation", "BuildOptions",
    "SteadyState", "build", "info", "steady", "stability", "run", "default_integration", "modes",
    "campbell", "compare")},
    "RunResult": "fxflex.time", "Modes": "fxflex.analysis.modes",
    "CampbellData": "fxflex.analysis.modes"}
#: subpackages a user reaches as attributes (``fxflex.cache.bypass()``)
_SUBMODULES = ("api", "cache")

__all__ = ["__version__", *_LAZY, *_SUBMODULES]


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    if name in _SUBMODULES:
        return importlib.import_module(f"fxflex.{name}")
    raise AttributeError(f"module 'fxflex' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
