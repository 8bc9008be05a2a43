"""The figures of ``fxflex compare`` (:mod:`fxflex.analysis.compare`), one function per study,
drawn from a :class:`~fxflex.analysis.compare.Compare`'s results by :mod:`fxflex.analysis.plots`
into its output folder (rank 0); each name drawn is appended to ``cmp.figures``."""

from __future__ import annotations

import numpy as np

from fxflex.analysis.compare_plan import DAMPING_RPM
from fxflex.analysis.transient import CaseResult
from fxflex.scene import PAPER_RPM

__all__ = ["speeds", "steps", "damping", "damping_steady", "bounded"]


def speeds(cmp, cases) -> None:
    """Fig. 4, 6, 7 equivalents (tip deflection per speed) and the drive torque."""
    from fxflex.analysis.plots import speed_figure, torque_figure

    names = {PAPER_RPM[0]: "fig4", PAPER_RPM[1]: "fig6", PAPER_RPM[2]: "fig7"}
    torque = {}
    for rpm in PAPER_RPM:
        runs, steady = {}, {}
        for c in cases:
            if c.rpm != rpm:
                continue
            d = bounded(cmp.results[c.key], c.t_end)
            s = cmp.summaries[("speeds", c.key)]
            runs[c.method] = (d[:, 0], d[:, 1:4], s["diverged"])
            st = cmp.steady_of(c)
            if st is not None:
                steady[c.method] = st.tip_m
            if "drive_torque_Nm" in cmp.results[c.key].columns:
                k = cmp.results[c.key].columns.index("drive_torque_Nm")
                torque.setdefault(rpm, {})[c.method] = (d[:, 0], d[:, k])
        name = f"{names[rpm]}_{rpm:g}rpm.png"
        speed_figure(cmp.path(name), rpm, runs, steady, f"Fig. {names[rpm][3:]} equivalent")
        cmp.figures.append(name)
    if torque:
        torque_figure(cmp.path("drive_torque.png"), torque)
        cmp.figures.append("drive_torque.png")

def steps(cmp, cases) -> None:
    """Fig. 5 equivalent: the orthogonal deflection at each step, per method."""
    from fxflex.analysis.plots import steps_figure

    panels = {}
    for c in cases:
        d = bounded(cmp.results[c.key], c.t_end)
        label = f"{c.dt * 1e6:.4g} us" + (f" {c.mass}" if c.mass else "")
        panels.setdefault(c.method, []).append(
            (label, d[:, 0], d[:, 2], cmp.summaries[("steps", c.key)]["diverged"]))
    steps_figure(cmp.path("fig5_steps.png"), panels)
    cmp.figures.append("fig5_steps.png")

def damping(cmp, cases) -> None:
    """Fig. 8-11 equivalents: the damping transients per model and speed."""
    from fxflex.analysis.plots import damping_figure

    names = {("relative", DAMPING_RPM[0]): "fig8", ("relative", DAMPING_RPM[1]): "fig9",
             ("absolute", DAMPING_RPM[0]): "fig10", ("absolute", DAMPING_RPM[1]): "fig11"}
    for (model, rpm), fig in names.items():
        panels = {}
        for c in cases:
            if (c.model, c.rpm) != (model, rpm):
                continue
            d = bounded(cmp.results[c.key], c.t_end)
            st = cmp.steady_of(c)
            panels.setdefault(c.method, []).append(
                (c.c, d[:, 0], d[:, 2], None if st is None else st.tip_m[1],
                 cmp.summaries[("damping", c.key)]["diverged"]))
        if panels:
            name = f"{fig}_{model}_{rpm:g}rpm.png"
            damping_figure(cmp.path(name), f"Fig. {fig[3:]} equivalent: {model} damping, "
                                            f"{rpm:g} rpm", panels)
            cmp.figures.append(name)


def damping_steady(cmp) -> None:
    """The damping study's equilibria against c, per model and speed."""
    from fxflex.analysis.plots import damping_steady_figure

    damping_steady_figure(cmp.path("damping_steady.png"), [r.as_dict() for r in cmp.damping],
                          DAMPING_RPM)
    cmp.figures.append("damping_steady.png")


def bounded(result: CaseResult, t_end: float) -> np.ndarray:
    """The run's finite samples up to ``t_end`` (half a step of slack)."""
    d = result.bounded()
    return d[d[:, 0] <= t_end + 0.5 * result.case.dt]
