"""What ``fxflex compare`` runs (:mod:`fxflex.analysis.compare`): the paper's speeds, dampings,
steps and windows, the row of an equilibrium, and the transients of each study."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from fxflex.analysis.transient import Case
from fxflex.formulation import PAPER_INTEGRATION
from fxflex.scene import PAPER_DAMPING, PAPER_RPM, Scene

__all__ = ["SteadyRow", "steady_time", "plan", "PAPER_WINDOW", "TLF_WINDOWS", "SAMPLE_DT",
           "DAMPING_METHODS", "DAMPING_RPM", "DAMPING_STEP", "GROWTH_LIMIT", "STEP_FACTORS",
           "LINEAR", "C3", "SHORT_WINDOWS", "MASS_CASES", "ACCURATE_SOLIDS"]

#: the window used for the paper's figures where the paper's text gives none (s)
PAPER_WINDOW = 0.02
#: TLF's default windows per study (s); ``--full`` uses PAPER_WINDOW
TLF_WINDOWS = {"speeds": 2e-3, "steps": 1e-3, "damping": 1e-3}
#: sampling interval of every transient (s)
SAMPLE_DT = 5e-6
#: the paper's damping study: methods, speeds, and GCMS's step there (Sect. 4.3)
DAMPING_METHODS = ("gcms", "tlf", "ancf")
DAMPING_RPM = (PAPER_RPM[0], PAPER_RPM[2])
DAMPING_STEP = {"gcms": 0.1e-6}
#: methods whose transients run on shorter windows unless ``--full`` (their cost per step)
SHORT_WINDOWS = {"tlf": TLF_WINDOWS}
#: extra cases of the step study: (--mass, step factor) of the methods with a mass option
MASS_CASES = {"tlf": (("consistent", 1.2),)}
#: how far a run about an unstable equilibrium may grow (m): far enough for a clean growth rate
GROWTH_LIMIT = 100.0
#: the step study's multiples of the paper step (Fig. 5: half, selected, slightly larger)
STEP_FACTORS = (0.5, 1.0, 1.2)
LINEAR = ("ffrf", "gcms", "lebb")
C3 = PAPER_DAMPING[2]
#: the accurate solids of study 1b (issue 13 item 5): 27-node hexahedra on 32 x 4 x 2, 8640
#: unknowns against the paper Q1 mesh's 27300, within 0.1 % of the converged reference on the
#: default blade (docs/accuracy.md), where the Q1 mesh is 1.6-2.2 % stiff
ACCURATE_SOLIDS = {"mesh.solid_degree": 2, "mesh.solid": (32, 4, 2)}


@dataclass
class SteadyRow:
    method: str
    rpm: float
    tip_m: np.ndarray
    stable: bool | None
    converged: bool
    dof: int
    seconds: float
    c: float = C3
    model: str = "relative"
    growth_rate: float | None = None
    sigma_max: float | None = None      # root-section sigma_X, Pa
    sigma_min: float | None = None
    torque: float | None = None         # drive torque at the equilibrium, N m
    extra: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        d = {k: v for k, v in asdict(self).items() if k not in ("tip_m", "extra")}
        d["tip_mm"] = [float(x) if math.isfinite(x) else None for x in 1e3 * self.tip_m]
        return d


def steady_time(scene: Scene) -> float:
    """A time after the load ramp at which the hub has turned a whole number of times: there the
    method's state equals the steady state's q (given at phi = 0) with the full load."""
    ramp, w = scene.load.ramp_time, scene.rotation.omega
    if w == 0.0:
        return max(ramp, 0.0)
    period = 2.0 * math.pi / w
    return period * max(1, math.ceil(ramp / period))


def plan(methods, full: bool, paper_window: float = PAPER_WINDOW,
         tlf_windows: dict | None = None) -> dict[str, list[Case]]:
    """The transients of studies 3-5 (module docstring) for ``methods``; the windows can be
    shortened (tests)."""
    short = dict(SHORT_WINDOWS, **({"tlf": tlf_windows} if tlf_windows else {}))

    def window(method, study):
        return paper_window if full or method not in short else short[method][study]

    out = {"speeds": [], "steps": [], "damping": []}
    for m in methods:
        integ, dt = PAPER_INTEGRATION[m]
        for rpm in PAPER_RPM:
            out["speeds"].append(Case(m, rpm, C3, "relative", integ, dt, window(m, "speeds")))
        for f in STEP_FACTORS:
            out["steps"].append(Case(m, PAPER_RPM[0], C3, "relative", integ, f * dt,
                                     window(m, "steps")))
        for mass, factor in MASS_CASES.get(m, ()):
            out["steps"].append(Case(m, PAPER_RPM[0], C3, "relative", integ, factor * dt,
                                     window(m, "steps"), mass=mass))
        if m in DAMPING_METHODS:
            step = DAMPING_STEP.get(m, dt)
            for model in ("relative", "absolute"):
                for rpm in DAMPING_RPM:
                    for c in PAPER_DAMPING:
                        out["damping"].append(Case(m, rpm, c, model, integ, step,
                                                   window(m, "damping")))
    return out
