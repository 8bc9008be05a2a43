"""Modes of the motion about the rotating steady state, for every method (SPEC sections 6 and 8).

Each formulation offers ``rotating_modes(pairs)`` -> the lowest roots lambda of
(lambda^2 M + lambda C + K) x = 0, one per conjugate pair, and their mode vectors (dense
companion form for the reduced and beam models, :mod:`fxflex.numerics.qep`; SLEPc PEP for TLF,
:mod:`fxflex.numerics.petsc`), and ``mode_tip(X)`` -> the tip section's translation and rotation in
each mode. From them: the frequency |Im lambda| / 2 pi (0 for a real root), the growth rate
Re lambda, and from ``mode_span(X)`` the mode shapes along the span and their participation
(:mod:`fxflex.analysis.shapes`, SPEC section 10): the fractions of each mode's kinetic energy in

- ``axial`` motion (along X),
- ``in-plane`` (along Y, in the plane of rotation),
- ``out-of-plane`` (along Z, the rotation axis, the load direction),
- ``torsion`` (the sections turning about X),

and its label, the family with the largest fraction. Mode vectors are complex (gyroscopic
coupling). The tracker of ``--campbell`` still names a candidate by its tip
(:func:`direction_labels`: whichever of |U_X|, |U_Y|, |U_Z| and r |theta_X| is largest, r the
polar radius of gyration sqrt((b^2 + h^2) / 12) of the tip section).

A Campbell diagram repeats this over a range of speeds (:func:`campbell`); ``fxflex modes
--campbell`` follows each mode from speed to speed by MAC (:func:`campbell_tracked`,
:mod:`fxflex.analysis.tracking`).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import sys
import time
from dataclasses import dataclass

import numpy as np

from fxflex.analysis.shapes import Shapes, mode_shapes
from fxflex.scene import Scene

__all__ = ["LABELS", "Modes", "direction_labels", "tip_radius", "modes_of", "speed_builder",
           "campbell", "CampbellData", "plot_campbell", "parse_range",
           "check_speeds", "sample_of", "campbell_tracked", "tracking_lines", "EXPORT_PAIRS",
           "modes_for_export", "elastodyn_export", "single_speed", "run_modes"]

LABELS = ("axial", "in-plane", "out-of-plane", "torsion")


@dataclass
class Modes:
    """Lowest modes about the rotating equilibrium at one speed, lowest frequency first."""

    rpm: float
    eigenvalues: np.ndarray         # (k,) complex, Im >= 0
    tip: np.ndarray                 # (6, k) complex tip translation and rotation per mode
    labels: list[str]
    stable: bool | None             # the formulation's verdict (stable()); None: undecided
    seconds: float = 0.0
    warnings: list[str] = dataclasses.field(default_factory=list)
    shapes: Shapes | None = None    # along the span, with the participation (SPEC section 10)

    @property
    def participation(self) -> list[dict[str, float]]:
        """Per mode the kinetic-energy fractions axial, in-plane, out-of-plane, torsion."""
        return self.shapes.participation if self.shapes is not None else []

    @property
    def frequencies_hz(self) -> np.ndarray:
        return np.abs(self.eigenvalues.imag) / (2.0 * math.pi)

    @property
    def growth_rates(self) -> np.ndarray:
        return self.eigenvalues.real

    @property
    def damping_ratios(self) -> np.ndarray:
        """-Re lambda / |lambda| per mode (SPEC section 10; 0 for a root at the origin)."""
        from fxflex.numerics.qep import damping_ratios
        return damping_ratios(self.eigenvalues)

    def to_dict(self) -> dict:
        """The SPEC section 8 fields, and section 10's damping ratios, participation and
        shapes: equal-length lists, one entry per conjugate pair."""
        shapes = self.shapes.to_dict() if self.shapes is not None else {"x": [], "modes": []}
        return {"rpm": self.rpm, "frequencies_hz": self.frequencies_hz.tolist(),
                "growth_rates": self.growth_rates.tolist(),
                "damping_ratios": self.damping_ratios.tolist(), "labels": list(self.labels),
                "participation": self.participation, "shapes": shapes,
                "stable": self.stable, "warnings": list(self.warnings)}


def direction_labels(tip: np.ndarray, radius: float) -> list[str]:
    """One label per column of the (6, k) tip motion (module docstring)."""
    amp = np.abs(np.vstack([tip[:3], radius * tip[3:4]]))
    return [LABELS[i] for i in np.argmax(amp, axis=0)]


def tip_radius(scene: Scene) -> float:
    """Polar radius of gyration of the tip section, sqrt((b^2 + h^2) / 12)."""
    g = scene.geometry
    return math.sqrt((g.tip_y**2 + g.tip_z**2) / 12.0)


def modes_of(form, pairs: int) -> Modes:
    """The ``pairs`` lowest modes of a built formulation at its scene's speed. Collective for
    TLF (every rank of its communicator must call).

    Nothing computed is dropped: a model with fewer modes than ``pairs`` gives all it has (the
    dense models every root, TLF at most ``dof`` pairs) with a warning saying so, and when the
    eigensolver converges fewer roots than asked those it has are reported, with the verdict
    None unless one of them grows (:func:`fxflex.numerics.qep.verdict`)."""
    from fxflex.numerics.qep import EigenNotConverged, verdict

    t0 = time.perf_counter()
    warnings = list(form.warnings)
    try:
        lam, X = form.rotating_modes(pairs)
    except EigenNotConverged as exc:
        lam, X = exc.eigenvalues, exc.vectors
        warnings.append(f"modes: {exc}; the {lam.size} converged are reported")
        converged = False
    else:
        converged = True
        if lam.size < pairs:
            warnings.append(f"--n {pairs}: {type(form).__name__.lower()} has {lam.size} modes "
                            f"(one per conjugate pair of the roots of its {form.dof} unknowns); "
                            f"all {lam.size} are reported")
    tip = form.mode_tip(X) if lam.size else np.zeros((6, 0), dtype=complex)
    if lam.size:
        x, S = form.mode_span(X)
        shapes = mode_shapes(form.scene, x, S)
        labels = shapes.labels
    else:
        shapes, labels = None, []
    stable, why = verdict(form)
    if why is not None and converged:
        warnings.append(why)
    return Modes(rpm=form.scene.rotation.rpm, eigenvalues=lam, tip=tip, labels=labels,
                 stable=stable, seconds=time.perf_counter() - t0, warnings=warnings,
                 shapes=shapes)


def speed_builder(method: str, scene: Scene, comm, options=None):
    """``build_at(rpm)``: the formulation of ``scene`` at another speed, the first build's
    ``at(rpm=...)`` (FFRF and GCMS share its mesh, operators, modes and projections, which do
    not depend on the speed; the beams are built afresh, in milliseconds). TLF's come from a
    :class:`~fxflex.solid.tlf_sweep.SpeedSweep`: one SolidModel, each steady state continued
    from the equilibria already found and each PEP started from the nearest speed's modes, the
    results those of a cold build to the solvers' tolerances."""
    from fxflex.formulation import build

    if method == "tlf":
        from fxflex.solid.tlf_sweep import SpeedSweep
        return SpeedSweep(scene, comm, options).at
    first = []

    def build_at(rpm: float):
        if first:
            return first[0].at(rpm=rpm)
        first.append(build(method, scene.replace(**{"rotation.rpm": float(rpm)}), comm, options))
        return first[0]

    return build_at


# -- Campbell diagram -------------------------------------------------------------------------------

def parse_range(text: str) -> tuple[float, float, int]:
    """``RPM_MIN:RPM_MAX:COUNT`` -> (min, max, count); ValueError naming what is wrong."""
    parts = text.split(":")
    if len(parts) != 3:
        raise ValueError(f"expected RPM_MIN:RPM_MAX:COUNT, got {text!r}")
    try:
        lo, hi, count = float(parts[0]), float(parts[1]), int(parts[2])
    except ValueError:
        raise ValueError(f"expected two numbers and an integer, got {text!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo < 0 or hi <= lo or count < 2:
        raise ValueError(f"need 0 <= RPM_MIN < RPM_MAX and COUNT >= 2, got {text!r}")
    return lo, hi, count


def check_speeds(scene: Scene, speeds) -> None:
    """Each speed of a Campbell range passes the validation ``--rpm`` passes (the scene's own,
    :func:`fxflex.scene.validate`), before anything is built; the first that fails ends with one
    line naming ``--campbell``."""
    from fxflex.errors import FxflexError, SceneError
    from fxflex.scene import validate

    for rpm in speeds:
        try:
            validate(scene.replace(**{"rotation.rpm": float(rpm)}))
        except SceneError as exc:
            raise FxflexError(f"--campbell: the speed {float(rpm):g} rpm is refused as "
                              f"--rpm would be: {exc}") from None


@dataclass
class CampbellData:
    """The modes at the requested speeds ``rpm`` and, when they were followed by MAC, the
    tracked branches (:class:`fxflex.analysis.tracking.Tracking`, over the requested and the
    refined speeds)."""

    method: str
    rpm: np.ndarray                 # (s,)
    modes: list[Modes]
    tracking: object | None = None

    def table(self) -> tuple[np.ndarray, np.ndarray, list[list[str]]]:
        """(frequencies_hz (s, k), growth_rates (s, k), labels) padded with NaN / '' where a
        speed has fewer modes."""
        k = max(len(m.labels) for m in self.modes)
        f = np.full((len(self.modes), k), np.nan)
        g = np.full((len(self.modes), k), np.nan)
        labels = []
        for i, m in enumerate(self.modes):
            n = len(m.labels)
            f[i, :n], g[i, :n] = m.frequencies_hz, m.growth_rates
            labels.append(list(m.labels) + [""] * (k - n))
        return f, g, labels

    def unstable_ranges(self) -> list[tuple[float, float]]:
        """Speed intervals around the unstable samples, bounded halfway to the stable
        neighbours (the sampling's resolution)."""
        rpm = self.rpm
        bad = [m.stable is False for m in self.modes]
        edges = np.concatenate([[rpm[0]], 0.5 * (rpm[1:] + rpm[:-1]), [rpm[-1]]])
        out = []
        for i, b in enumerate(bad):
            if not b:
                continue
            lo, hi = edges[i], edges[i + 1]
            if out and math.isclose(out[-1][1], lo):
                out[-1] = (out[-1][0], hi)
            else:
                out.append((lo, hi))
        return [(float(a), float(b)) for a, b in out]


def campbell(build_at, speeds, pairs: int, progress=None) -> list[Modes]:
    """Modes at each speed; ``build_at(rpm)`` returns the formulation for that speed and
    ``progress(i, modes)`` is called after each."""
    out = []
    for i, rpm in enumerate(speeds):
        modes = modes_of(build_at(float(rpm)), pairs)
        out.append(modes)
        if progress is not None:
            progress(i, modes)
    return out


def sample_of(form, pairs: int, extra: int | None = None, requested: bool = True):
    """The :class:`~fxflex.analysis.tracking.Sample` at the formulation's speed: the ``pairs``
    reported modes (:func:`modes_of`) and ``pairs + extra`` candidates (default EXTRA_MODES)
    with their mass products and labels (the largest participation, as the reported modes').
    Collective for TLF. The candidates are solved first: the reported modes are the lowest of
    them (the formulation keeps its eigensolve)."""
    from fxflex.analysis.tracking import EXTRA_MODES, Sample, mass_times
    from fxflex.numerics.qep import EigenNotConverged

    extra = EXTRA_MODES if extra is None else extra
    t0 = time.perf_counter()
    try:
        lam, X = form.rotating_modes(pairs + extra)
    except EigenNotConverged as exc:
        lam, X = exc.eigenvalues, exc.vectors
        if X is None:
            lam, X = lam[:0], np.zeros((0, 0), dtype=complex)
    modes = modes_of(form, pairs)
    if lam.size:
        labels = mode_shapes(form.scene, *form.mode_span(X)).labels
        MX = mass_times(form, X)
    else:
        labels, MX = [], X
    modes.seconds = time.perf_counter() - t0           # the eigensolve is the candidates'
    return Sample(rpm=float(form.scene.rotation.rpm), modes=modes, lam=lam, X=X, MX=MX,
                  labels=labels, comm=form.comm if form.distributed else None,
                  requested=requested)


def campbell_tracked(build_at, speeds, pairs: int, method: str = "", progress=None):
    """Campbell branches over ``speeds`` tracked by MAC (:func:`fxflex.analysis.tracking.track`,
    refined where a MAC falls below 0.9) from the formulations ``build_at(rpm)``;
    ``progress(sample)`` is called after each speed computed."""
    from fxflex.analysis.tracking import track

    return track(lambda rpm, requested: sample_of(build_at(rpm), pairs, requested=requested),
                 speeds, pairs, method=method, progress=progress)


_COLOURS = {"axial": "tab:green", "in-plane": "tab:blue", "out-of-plane": "tab:orange",
            "torsion": "tab:purple"}


def plot_campbell(data: CampbellData, path: str, tracking=None) -> None:
    """Frequencies against speed, coloured by direction, the 1x..4x rotation lines, and the
    speed ranges where the equilibrium is unstable shaded (PNG, matplotlib Agg). With the
    ``tracking`` of :func:`fxflex.analysis.tracking.track` the lines are its branches (coloured by
    family, one line style per ordinal) and a black ring marks each speed where a branch's MAC to
    the previous speed stayed below the threshold (default: ``data.tracking``); without any, the
    j-th lowest mode of each direction is joined from speed to speed."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tracking = data.tracking if tracking is None else tracking
    fig, ax = plt.subplots(figsize=(7.5, 5.0))
    for lo, hi in data.unstable_ranges():
        ax.axvspan(lo, hi, color="tab:red", alpha=0.15, lw=0)
    if tracking is None:
        top = _plot_sorted(ax, data)
        rpm = data.rpm
    else:
        top = _plot_branches(ax, tracking)
        rpm = tracking.rpm
    styles = ("--", ":", "-.", (0, (6, 2, 1, 2, 1, 2)))
    for h, ls in zip(range(1, 5), styles):
        ax.plot(rpm, h * rpm / 60.0, color="k", ls=ls, lw=0.9, label=f"{h}x rotation")
    ax.set_ylim(0, 1.05 * max(top, 2 * rpm[-1] / 60.0))
    ax.set_xlim(rpm[0], rpm[-1])
    ax.set_xlabel("hub speed (rpm)")
    ax.set_ylabel("frequency in the rotating frame (Hz)")
    what = "branches tracked by MAC, " if tracking is not None else ""
    ax.set_title(f"Campbell diagram, {data.method.upper()} ({what}shaded: unstable equilibrium)",
                 fontsize=10)
    ax.legend(fontsize=7, loc="upper left", ncol=2)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _plot_sorted(ax, data: CampbellData) -> float:
    """The untracked drawing: points coloured by direction, thin lines joining the j-th lowest
    of each direction; the highest frequency drawn."""
    f, g, labels = data.table()
    # past a divergence speed an oscillating pair becomes two real roots +-a (0 Hz), of which
    # only the growing one continues the branch, so that the count stays aligned
    for lab in LABELS:
        branch = np.full_like(f, np.nan)
        for i in range(f.shape[0]):
            row = [f[i, j] for j in range(f.shape[1])
                   if labels[i][j] == lab and (f[i, j] > 0 or g[i, j] > 0)]
            branch[i, : len(row)] = row
        for j in range(branch.shape[1]):
            ax.plot(data.rpm, branch[:, j], color=_COLOURS[lab], alpha=0.4, lw=0.8, zorder=1)
    seen = set()
    for i, rpm in enumerate(data.rpm):
        for j, lab in enumerate(labels[i]):
            if not lab:
                continue
            growing = g[i, j] > 0
            ax.scatter(rpm, f[i, j], s=22 if growing else 14, marker="x" if growing else "o",
                       color="tab:red" if growing else _COLOURS[lab], zorder=3,
                       label=None if (lab, growing) in seen else
                       (f"{lab}, growing" if growing else lab))
            seen.add((lab, growing))
    return float(np.nanmax(f)) if np.isfinite(f).any() else 1.0


def _plot_branches(ax, tracking) -> float:
    """Each tracked branch as a line with small points at the speeds computed, growing roots as
    red crosses, rings where the MAC stayed below the threshold; the highest frequency drawn."""
    styles = ("-", "--", "-.", ":")
    count: dict[str, int] = {}
    top = 1.0
    low_seen = grow_seen = False
    for b in tracking.branches:
        k = count[b.family] = count.get(b.family, 0) + 1
        f, g = b.frequencies_hz, b.growth_rates
        ax.plot(tracking.rpm, f, color=_COLOURS[b.family], ls=styles[(k - 1) % 4], lw=1.2,
                marker="o", ms=2.5, label=b.label, zorder=2)
        grow = g > 0
        if grow.any():
            ax.scatter(tracking.rpm[grow], f[grow], s=24, marker="x", color="tab:red", zorder=3,
                       label=None if grow_seen else "growing")
            grow_seen = True
        low = b.mac < tracking.threshold
        if low.any():
            ax.scatter(tracking.rpm[low], f[low], s=60, facecolors="none", edgecolors="k",
                       lw=1.2, zorder=4,
                       label=None if low_seen else f"MAC < {tracking.threshold:g}")
            low_seen = True
        if np.isfinite(f).any():
            top = max(top, float(np.nanmax(f)))
    return top


# -- the ``fxflex modes`` command -------------------------------------------------------------------

def modes_table(modes: Modes) -> list[str]:
    """One line per mode: frequency, growth rate, label and the participation (axial, in-plane,
    out-of-plane, torsion fractions of the kinetic energy, SPEC section 10)."""
    lines = ["   #  frequency (Hz)  growth rate (1/s)  direction      participation X/Y/Z/T"]
    part = modes.participation or [None] * len(modes.labels)
    for i, (f, g, lab, p) in enumerate(zip(modes.frequencies_hz, modes.growth_rates,
                                           modes.labels, part)):
        frac = "" if p is None else " ".join(f"{p[k]:.3f}" for k in LABELS)
        lines.append(f"  {i + 1:2d}  {f:14.4f}  {g:+17.6g}  {lab:<13s}  {frac}")
    return lines


def _write_campbell(data: CampbellData, out_dir: str, payload: dict, tracking=None
                    ) -> dict[str, str]:
    """The PNG, the CSV of the modes at the requested speeds (one row per speed and mode), with
    ``tracking`` the CSV of its branches (one row per speed and branch), and the JSON."""
    import json

    from fxflex.io.payload import jsonable

    stem = os.path.join(out_dir, f"campbell_{data.method}")
    files = {"png": stem + ".png", "csv": stem + ".csv", "json": stem + ".json"}
    if tracking is not None:
        files["branches_csv"] = stem + "_branches.csv"
    plot_campbell(data, files["png"], tracking)
    with open(files["csv"], "w") as fh:
        fh.write("rpm,mode,frequency_hz,growth_rate_1_s,label,stable\n")
        for m in data.modes:
            for j, (f, g, lab) in enumerate(zip(m.frequencies_hz, m.growth_rates, m.labels)):
                fh.write(f"{m.rpm:g},{j + 1},{f:.10g},{g:.10g},{lab},{m.stable}\n")
    if tracking is not None:
        with open(files["branches_csv"], "w") as fh:
            fh.write("rpm,branch,family,frequency_hz,growth_rate_1_s,damping_ratio,mac,"
                     "direction,refined\n")
            for b in tracking.branches:
                rows = zip(tracking.rpm, b.frequencies_hz, b.growth_rates, b.damping_ratios,
                           b.mac, b.directions, tracking.requested)
                for rpm, f, g, z, mac, d, req in rows:
                    fh.write(f"{rpm:g},{b.label},{b.family},{f:.10g},{g:.10g},{z:.6g},"
                             f"{mac:.6f},{d},{not req}\n")
    with open(files["json"], "w") as fh:
        json.dump(jsonable({**payload, "files": files}), fh, indent=1)
    return files


def tracking_lines(tracking) -> list[str]:
    """The text of the tracked branches: per branch its frequencies at the ends, lowest MAC and
    where its family (largest participation) changes (a veering); then the resonance speeds."""
    lines = [f"  branches tracked by MAC over {tracking.rpm.size} speeds "
             f"({tracking.refined} added by refinement where a MAC fell below "
             f"{tracking.threshold:g}):"]
    for b in tracking.branches:
        f = b.frequencies_hz
        mac = np.nanmin(b.mac) if np.isfinite(b.mac).any() else float("nan")
        change = [i for i in range(1, len(b.directions))
                  if b.directions[i] and b.directions[i] != b.directions[i - 1]]
        turn = "; now " + ", ".join(f"{b.directions[i]} from {tracking.rpm[i]:g} rpm"
                                    for i in change) if change else ""
        lines.append(f"    {b.label:<20s} {f[0]:9.2f} -> {f[-1]:9.2f} Hz, lowest MAC "
                     f"{mac:.3f}{turn}")
    low = tracking.low_mac()
    if low:
        lines.append("  MAC below the threshold after refinement: " + ", ".join(
            f"{lab} at {rpm:g} rpm ({mac:.2f})" for lab, rpm, mac in low))
    if tracking.resonances:
        lines.append("  resonances (branch crosses h x rotation frequency):")
        for r in sorted(tracking.resonances, key=lambda r: r["rpm"]):
            lines.append(f"    {r['rpm']:9.1f} rpm  {r['harmonic']}x  {r['branch']}")
    else:
        lines.append("  resonances: no branch crosses the 1x..4x lines in the range")
    return lines


def _log_warnings(comm, notes: list[str]) -> None:
    """Each warning once on stderr, from rank 0 (the JSON carries them in ``warnings``)."""
    if comm.rank == 0:
        for note in notes:
            logging.getLogger("fxflex").warning(note)


#: ``--elastodyn``: at least this many modes are computed (flap 2 is the 3rd on the paper's blade
#: and on a uniform cantilever of any section aspect ratio; torsion can come before it)
EXPORT_PAIRS = 6
#: and while flap 1, flap 2 or edge 1 is not among them, twice as many, up to this count
EXPORT_MAX_PAIRS = 48
ELASTODYN_NOT_CAMPBELL = ("--elastodyn: not with --campbell (the shapes are fitted at one speed, "
                          "the scene's); allowed: --elastodyn with --rpm R")


def modes_for_export(compute, pairs: int, export: bool):
    """``compute(n)``: the result for ``n`` modes (a :class:`Modes`, or a tuple whose first item
    is one). Without ``export``, ``compute(pairs)``. With it (``--elastodyn``) max(pairs,
    EXPORT_PAIRS) modes, doubled up to EXPORT_MAX_PAIRS while the modes of flap 1, flap 2 or
    edge 1 (:func:`fxflex.analysis.elastodyn.choose_modes`) are not among them and the model has
    more: the export finds its modes whatever ``--n`` is, and every mode computed is reported."""
    from fxflex.analysis.elastodyn import missing_shapes

    n = max(pairs, EXPORT_PAIRS) if export else pairs
    while True:
        result = compute(n)
        modes = result[0] if isinstance(result, tuple) else result
        if (not export or len(modes.labels) < n or n >= EXPORT_MAX_PAIRS
                or not missing_shapes(modes.participation, modes.frequencies_hz)):
            return result
        n = min(2 * n, EXPORT_MAX_PAIRS)


def elastodyn_export(modes: Modes, scene: Scene, path: str) -> tuple[list, dict, list[str]]:
    """(fits, the JSON member ``elastodyn``, text lines) of the ElastoDyn mode shapes fitted to
    ``modes`` (:func:`fxflex.analysis.elastodyn.fit_modes`); FxflexError naming a shape that
    has no mode or cannot be fitted. ``mode`` is 1-based as in the table and the shapes CSV."""
    from fxflex.analysis.elastodyn import SHAPES, fit_modes, missing_shapes
    from fxflex.errors import FxflexError

    missing = missing_shapes(modes.participation, modes.frequencies_hz)
    if missing:
        found = ", ".join(f"{modes.labels.count(lab)} {lab}" for lab in LABELS
                          if lab in modes.labels) or "none"
        raise FxflexError(f"--elastodyn: no mode for {', '.join(missing)} among the "
                          f"{len(modes.labels)} modes computed ({found}); allowed: a scene whose "
                          "lowest modes include flap 1, flap 2 and edge 1")
    try:
        fits = fit_modes(modes.shapes, modes.frequencies_hz, scene.geometry.length)
    except ValueError as exc:
        raise FxflexError(f"--elastodyn: {exc}") from None
    member = {"file": os.path.abspath(path), "rpm": scene.rotation.rpm,
              "length_m": scene.geometry.length, "shapes": {}}
    lines = [f"  ElastoDyn mode shapes (polynomials in x / {scene.geometry.length:g} m, "
             f"coefficients of x^2..x^6 summing to 1):"]
    for fit, (stem, description, family, _, component) in zip(fits, SHAPES):
        j = fit.mode - 1
        member["shapes"][stem] = {**fit.to_dict(), "description": description,
                                  "family": family, "component": "XYZ"[component],
                                  "participation": modes.participation[j][family],
                                  "imag_ratio": float(modes.shapes.imag_ratio[j])}
        lines.append(f"    {stem}  {description}: mode {fit.mode} ({fit.frequency_hz:.4g} Hz), "
                     f"u_{'XYZ'[component]}, residual {fit.residual:.2g}")
    lines.append(f"  written: {member['file']}")
    return fits, member, lines


def single_speed(method: str, scene: Scene, comm, modes: Modes, dof: int, timings: dict,
                 out_dir: str | None, elastodyn: str | None, *, head: str, tail: str = "",
                 fields: dict | None = None) -> tuple[dict, str]:
    """``fxflex modes`` at one speed, with or without ``--tol`` (``fields``: its
    ``error_estimate`` and ``discretisation``): the payload (SPEC sections 8 and 10, and
    ``elastodyn``, null without the export), the text (``head``, the table, the verdict followed
    by ``tail``) and, from rank 0, the ElastoDyn file (written whole or not at all) and in
    ``out_dir`` ``modes_<method>.json``, ``shapes_<method>.csv`` and ``shapes_<method>.png``."""
    import json

    from fxflex.analysis.elastodyn import write_elastodyn
    from fxflex.analysis.shapes import plot_shapes, write_shapes_csv
    from fxflex.io import envelope

    fits, member, export_lines = (elastodyn_export(modes, scene, elastodyn)
                                  if elastodyn is not None else (None, None, []))
    payload = envelope(scene, method=method, dof=dof,
                       damping={"c": scene.damping.c, "model": scene.damping.model},
                       n=len(modes.labels), **modes.to_dict(), elastodyn=member,
                       timings_s=timings, **(fields or {}))
    text = [head, *modes_table(modes), f"  stable: {modes.stable}{tail}", *export_lines,
            *(f"  WARNING: {note}" for note in modes.warnings)]
    _log_warnings(comm, modes.warnings)
    if comm.rank != 0:
        return payload, "\n".join(text)
    if fits is not None:
        write_elastodyn(member["file"], fits, f"fxflex {method}, {scene.rotation.rpm:g} rpm")
    if out_dir is not None:
        os.makedirs(out_dir, exist_ok=True)
        path = os.path.join(out_dir, f"modes_{method}.json")
        with open(path, "w") as fh:
            json.dump(payload, fh, indent=1)
        text.append(f"  written: {path}")
        if modes.shapes is not None:
            stem = os.path.join(out_dir, f"shapes_{method}")
            write_shapes_csv(modes.shapes, stem + ".csv")
            plot_shapes(modes.shapes, stem + ".png", modes.frequencies_hz,
                        f"{method.upper()} mode shapes at {scene.rotation.rpm:g} rpm "
                        f"(largest translation 1)")
            text.append(f"  written: {stem}.csv, {stem}.png")
    return payload, "\n".join(text)


def run_modes(method: str, scene: Scene, comm, options, pairs: int, campbell_spec: str | None,
              out_dir: str | None, elastodyn: str | None = None) -> tuple[dict, str]:
    """``fxflex modes``: (JSON payload with the envelope, human-readable text). Files go to
    ``out_dir`` from rank 0: the Campbell PNG, CSV and JSON, or those of :func:`single_speed`;
    ``elastodyn`` (one speed only) the ElastoDyn file's path."""
    from fxflex.errors import FxflexError
    from fxflex.formulation import build
    from fxflex.io import envelope

    speeds = None
    if campbell_spec is not None:
        if elastodyn is not None:
            raise FxflexError(ELASTODYN_NOT_CAMPBELL)
        try:
            lo, hi, count = parse_range(campbell_spec)
        except ValueError as exc:
            raise FxflexError(f"--campbell: {exc}") from None
        speeds = np.linspace(lo, hi, count)
        check_speeds(scene, speeds)
    if out_dir is not None and os.path.exists(out_dir) and not os.path.isdir(out_dir):
        raise FxflexError(f"--out: {out_dir} exists and is not a directory")
    damping = {"c": scene.damping.c, "model": scene.damping.model}
    if speeds is None:
        t0 = time.perf_counter()
        form = build(method, scene, comm, options)
        t1 = time.perf_counter()
        modes = modes_for_export(lambda n: modes_of(form, n), pairs, elastodyn is not None)
        timings = {"preprocess": t1 - t0, "solve": time.perf_counter() - t1}
        head = (f"{method} modes about the steady state at {scene.rotation.rpm:g} rpm (dof "
                f"{form.dof}, damping c = {scene.damping.c:g} {scene.damping.model})")
        tail = (f"   preprocess {timings['preprocess']:.2f} s, steady state + eigenvalues "
                f"{timings['solve']:.2f} s")
        # SPEC 9: without --tol both are null, in the saved JSON as on stdout
        return single_speed(method, scene, comm, modes, form.dof, timings, out_dir, elastodyn,
                            head=head, tail=tail, fields={"error_estimate": None,
                                                          "discretisation": None})

    done = []

    def progress(sample):
        m = sample.modes
        if sample.requested:
            done.append(m)
        if comm.rank == 0:
            f = m.frequencies_hz
            where = (f"({len(done)}/{len(speeds)})" if sample.requested else "refined")
            sys.stderr.write(f"  {method} {m.rpm:8.1f} rpm {where}: lowest "
                             f"{f[0]:.2f} Hz, max growth {m.growth_rates.max():+.4g} 1/s, "
                             f"{ {True: 'stable', False: 'UNSTABLE'}.get(m.stable, 'undecided')}"
                             f"  {m.seconds:.1f} s\n")
            sys.stderr.flush()

    if comm.rank == 0:
        sys.stderr.write(f"fxflex modes: {method} Campbell diagram, {len(speeds)} speeds from "
                         f"{speeds[0]:g} to {speeds[-1]:g} rpm, {pairs} modes each, tracked by "
                         f"MAC\n")
    t0 = time.perf_counter()
    tracking = campbell_tracked(speed_builder(method, scene, comm, options), speeds, pairs,
                                method, progress)
    modes = [s.modes for s in tracking.samples if s.requested]
    data = CampbellData(method, speeds, modes, tracking)
    ranges = data.unstable_ranges()
    payload = envelope(scene, method=method, damping=damping, n=pairs, campbell={
        "rpm": speeds.tolist(), "frequencies_hz": [m.frequencies_hz.tolist() for m in modes],
        "growth_rates": [m.growth_rates.tolist() for m in modes],
        "labels": [m.labels for m in modes], "stable": [m.stable for m in modes],
        "unstable_rpm": ranges},
        **tracking.to_dict(), refined_rpm=tracking.rpm[~tracking.requested].tolist(),
        low_mac=[{"branch": lab, "rpm": rpm, "mac": mac}
                 for lab, rpm, mac in tracking.low_mac()],
        warnings=list(dict.fromkeys(w for s in tracking.samples for w in s.modes.warnings)),
        timings_s={"total": time.perf_counter() - t0})
    files = {}
    if comm.rank == 0:
        os.makedirs(out_dir, exist_ok=True)
        files = _write_campbell(data, out_dir, payload, tracking)
    files = comm.bcast(files, root=0)
    payload["files"] = files
    text = [f"{method} Campbell diagram, {len(speeds)} speeds, {pairs} modes each "
            f"({payload['timings_s']['total']:.1f} s)",
            "  unstable equilibrium: " + (", ".join(f"{a:g}-{b:g} rpm" for a, b in ranges)
                                          if ranges else "nowhere in the range"),
            *tracking_lines(tracking),
            *(f"  {k}: {v}" for k, v in files.items()),
            *(f"  WARNING: {note}" for note in payload["warnings"])]
    _log_warnings(comm, payload["warnings"])
    return payload, "\n".join(text)
