"""PNG figures of ``fxflex compare`` (matplotlib, Agg backend; imported only when a figure is drawn).

Every function takes plain arrays (time in s, deflections in m) and a path, draws one figure and
closes it. Linear methods (FFRF, GCMS, LEBB) are dashed, nonlinear ones (TLF, NEBB, ANCF) solid,
each method in the same colour in every figure.
"""

from __future__ import annotations

import numpy as np

__all__ = ["speed_figure", "steps_figure", "damping_figure", "damping_steady_figure",
           "torque_figure", "LINEAR"]

LINEAR = ("ffrf", "gcms", "lebb")
COLOURS = {"ffrf": "C0", "gcms": "C1", "lebb": "C2", "tlf": "C3", "nebb": "C4", "ancf": "C5"}
COMPONENT_NAMES = ("longitudinal", "orthogonal", "load")


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _clip_to_bounded(ax, bounded: list) -> None:
    """Scale the y axis to the runs that stayed bounded (a divergent run would flatten them);
    divergent runs then leave the panel, their stop marked by a vertical line."""
    vals = [np.asarray(y)[np.isfinite(y)] for y in bounded]
    vals = [v for v in vals if v.size]
    if not vals:
        return
    lo, hi = min(v.min() for v in vals), max(v.max() for v in vals)
    pad = 0.25 * (hi - lo) if hi > lo else max(abs(hi), 1e-9)
    ax.set_ylim(lo - pad, hi + pad)


def _style(method: str) -> dict:
    return {"color": COLOURS.get(method, "k"), "ls": "--" if method in LINEAR else "-",
            "lw": 1.0, "label": method.upper()}


def speed_figure(path: str, rpm: float, runs: dict, steady: dict, title: str) -> None:
    """Tip deflection histories at one speed (the paper's Fig. 4, 6, 7): rows longitudinal,
    orthogonal, load; left column the linear methods, right the nonlinear ones. ``runs`` maps a
    method to (t, tip (n, 3), diverged time or None); ``steady`` a method to its equilibrium
    deflection (drawn as a thin dotted line)."""
    plt = _pyplot()
    fig, axes = plt.subplots(3, 2, figsize=(11, 8), sharex=True)
    for col, group in enumerate((lambda m: m in LINEAR, lambda m: m not in LINEAR)):
        for method, (t, tip, div) in runs.items():
            if not group(method):
                continue
            for k in range(3):
                ax = axes[k, col]
                ax.plot(1e3 * t, 1e3 * tip[:, k], **_style(method))
                if method in steady:
                    ax.axhline(1e3 * steady[method][k], color=COLOURS[method], ls=":", lw=0.8)
                if div is not None:
                    ax.axvline(1e3 * t[-1], color=COLOURS[method], ls=":", lw=0.8)
        for k in range(3):
            _clip_to_bounded(axes[k, col], [1e3 * tip[:, k] for m, (t, tip, div) in runs.items()
                                            if group(m) and div is None])
        axes[0, col].set_title(("linear" if col == 0 else "nonlinear") + " methods")
        axes[2, col].set_xlabel("t (ms)")
        axes[0, col].legend(loc="best", fontsize=8)
    for k, name in enumerate(COMPONENT_NAMES):
        axes[k, 0].set_ylabel(f"{name} (mm)")
    fig.suptitle(f"{title}: free-end deflection at {rpm:g} rpm (dotted: equilibrium; "
                 f"vertical: divergence stop)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def steps_figure(path: str, panels: dict) -> None:
    """Orthogonal deflection under different steps (the paper's Fig. 5): one panel per method,
    ``panels[method] = [(label, t, orthogonal, diverged), ...]``."""
    plt = _pyplot()
    n = len(panels)
    cols = min(n, 3)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    for ax, (method, lines) in zip(axes.flat, panels.items()):
        for i, (label, t, y, div) in enumerate(lines):
            ax.plot(1e3 * t, 1e3 * y, lw=1.0, ls=("-", "--", ":", "-.")[i % 4],
                    label=label + (" (diverged)" if div else ""))
            if div:
                ax.axvline(1e3 * t[-1], color=f"C{i}", ls=":", lw=0.8)
        _clip_to_bounded(ax, [1e3 * y for _, _, y, div in lines if not div])
        ax.set_title(method.upper())
        ax.set_xlabel("t (ms)")
        ax.set_ylabel("orthogonal (mm)")
        ax.legend(fontsize=7)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    fig.suptitle("Orthogonal deflection under different time steps (1000 rpm, c3)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def damping_figure(path: str, title: str, panels: dict) -> None:
    """Orthogonal deflection for c1..c3 (the paper's Fig. 8-11): one column per method,
    ``panels[method] = [(c, t, orthogonal, steady orthogonal or None, diverged), ...]`` with c1
    first. The curves of different c nearly coincide over short windows, so the second row shows
    each one's difference from the c1 run (dotted: the difference of the equilibria)."""
    plt = _pyplot()
    n = len(panels)
    fig, axes = plt.subplots(2, n, figsize=(4.4 * n, 5.8), squeeze=False, sharex="col")
    for j, (method, lines) in enumerate(panels.items()):
        ax, dax = axes[0, j], axes[1, j]
        _, t1, y1, st1, _ = lines[0]
        for i, (c, t, y, st, div) in enumerate(lines):
            colour = f"C{i}"
            ax.plot(1e3 * t, 1e3 * y, color=colour, lw=1.0,
                    label=f"c = {c:g}" + (" (diverged)" if div else ""))
            if st is not None:
                ax.axhline(1e3 * st, color=colour, ls=":", lw=0.8)
            if div:
                ax.axvline(1e3 * t[-1], color=colour, ls="-.", lw=0.8)
            m = min(len(t), len(t1))
            dax.plot(1e3 * t[:m], 1e3 * (y[:m] - y1[:m]), color=colour, lw=1.0)
            if st is not None and st1 is not None:
                dax.axhline(1e3 * (st - st1), color=colour, ls=":", lw=0.8)
        _clip_to_bounded(ax, [1e3 * y for _, _, y, _, div in lines if not div])
        ax.set_title(method.upper())
        ax.set_ylabel("orthogonal (mm)")
        ax.legend(fontsize=7)
        dax.set_xlabel("t (ms)")
        dax.set_ylabel("difference from c1 (mm)")
    fig.suptitle(title + " (dotted: equilibria)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def damping_steady_figure(path: str, rows: list[dict], speeds) -> None:
    """Equilibrium orthogonal deflection against c for both damping models, one panel per speed;
    ``rows`` carry method, rpm, c, model and tip_mm."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(speeds), figsize=(5.5 * len(speeds), 3.8), squeeze=False)
    for ax, rpm in zip(axes.flat, speeds):
        for method in COLOURS:
            for model, ls, mk in (("relative", "-", "o"), ("absolute", "--", "s")):
                pts = sorted((r["c"], r["tip_mm"][1]) for r in rows if r["method"] == method
                             and r["rpm"] == rpm and r["model"] == model
                             and r["tip_mm"][1] is not None)
                if pts:
                    c, y = np.array(pts).T
                    ax.plot(c, y, ls=ls, marker=mk, color=COLOURS[method], ms=4,
                            label=f"{method.upper()} {model}")
        ax.set_title(f"{rpm:g} rpm")
        ax.set_xlabel("c (kg s^-1 m^-3)")
        ax.set_ylabel("equilibrium orthogonal (mm)")
    axes.flat[0].legend(fontsize=6, ncol=2)
    fig.suptitle("Damping models: equilibrium orthogonal deflection against c")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def torque_figure(path: str, panels: dict) -> None:
    """Drive torque histories, one panel per speed: ``panels[rpm] = {method: (t, torque)}``."""
    plt = _pyplot()
    n = len(panels)
    fig, axes = plt.subplots(1, n, figsize=(4.6 * n, 3.4), squeeze=False)
    for ax, (rpm, runs) in zip(axes.flat, panels.items()):
        for method, (t, tau) in runs.items():
            ax.plot(1e3 * t, tau, **_style(method))
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_title(f"{rpm:g} rpm")
        ax.set_xlabel("t (ms)")
        ax.set_ylabel("drive torque (N m)")
        ax.legend(fontsize=7)
    fig.suptitle("Drive torque holding the prescribed rotation (relative damping, c3)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
