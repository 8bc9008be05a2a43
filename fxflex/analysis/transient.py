"""One transient of the paper's study: run it, write it as it goes, and read it.

A :class:`Case` is a method at a speed, damping coefficient and model, with an integrator, a step
and a window. :func:`run_case` integrates it with the one time loop (:func:`fxflex.time.simulate`),
sampling the free-end deflection, whatever extra outputs the method offers (the drive torque) and
the largest and smallest axial stress at the root section's corners (the method's
``root_stress``), writes the samples to a CSV file as they come and returns them with a summary:
the deflection at the end, the Hann-weighted mean over the window (the value the transient
oscillates about), the peaks, and for a divergent run its cause (physical or numerical,
:func:`fxflex.time.diagnose`) and the measured exponential growth of its deviation from the
equilibrium next to the eigenvalue of the linearised rotating system.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from fxflex.analysis.signals import hann_mean
from fxflex.io import Progress, SeriesWriter
from fxflex.time import diagnose, divergence_limit, simulate
from fxflex.time.diagnosis import deviation_growth

__all__ = ["Case", "CaseResult", "run_case", "summarise", "COLUMNS"]

#: the columns every case writes after its extras: root-section sigma_X, largest and smallest (Pa)
STRESS_COLUMNS = ("sigma_root_max_Pa", "sigma_root_min_Pa")
COLUMNS = ("t_s", "longitudinal_m", "orthogonal_m", "load_m")


@dataclass(frozen=True)
class Case:
    """One transient: ``mass`` is TLF's mass matrix (None: the default)."""

    method: str
    rpm: float
    c: float
    model: str
    integrator: str
    dt: float
    t_end: float
    mass: str | None = None

    @property
    def key(self) -> tuple:
        """Everything but the window: two cases with the same key share one run."""
        return (self.method, self.rpm, self.c, self.model, self.integrator, self.dt, self.mass)

    @property
    def name(self) -> str:
        mass = f"_{self.mass}" if self.mass else ""
        return (f"{self.method}_{self.rpm:g}rpm_c{self.c:g}_{self.model}_{self.integrator}"
                f"_dt{self.dt * 1e6:.4g}us{mass}")

    def label(self) -> str:
        mass = f", {self.mass} mass" if self.mass else ""
        return (f"{self.method.upper()}-{self.integrator.upper()} {self.rpm:g} rpm c={self.c:g} "
                f"{self.model}, dt={self.dt * 1e6:.4g} us{mass}")


@dataclass
class CaseResult:
    case: Case
    columns: list[str]
    data: np.ndarray            # (samples, columns): t, tip (3), extras, sigma max/min
    steps: int
    wall_s: float
    diverged: dict | None       # None or fxflex.time.diagnose's dict
    dof: int
    limit: float                # the driver's divergence limit (m)

    def divergence_time(self) -> float | None:
        """First sample past the driver's divergence limit (or non-finite), None if bounded."""
        if self.diverged is None:
            return None
        tip = self.data[:, 1:4]
        past = ~np.all(np.isfinite(tip), axis=1) | (np.nanmax(np.abs(tip), axis=1) > self.limit)
        return float(self.data[past, 0][0]) if past.any() else self.diverged["time_s"]

    def bounded(self) -> np.ndarray:
        """The samples up to the divergence time (all of them for a bounded run)."""
        td = self.divergence_time()
        return self.data if td is None else self.data[self.data[:, 0] <= td]

    def window(self, t_end: float) -> np.ndarray:
        """The samples up to t_end (a longer run read over a shorter window); half a step of
        slack keeps a run's last sample, at round(t_end / dt) steps."""
        return self.data[self.data[:, 0] <= t_end + 0.5 * self.case.dt]

    def column(self, name: str, t_end: float | None = None) -> np.ndarray:
        d = self.data if t_end is None else self.window(t_end)
        return d[:, self.columns.index(name)]


def run_case(form, case: Case, *, sample_dt: float, csv_path: str | None, meta: dict,
             enabled: bool = True, limit: float | None = None) -> CaseResult:
    """Integrate ``form`` (built for the case's scene) over the case's window, sampling every
    ``sample_dt`` (rounded to whole steps) and writing each sample to ``csv_path`` (rank 0 only,
    when ``enabled``). The root stress is collective for the solid methods: every rank calls.

    ``limit``: the deflection (m) at which the run stops, by default the driver's divergence
    limit (a quarter of the beam length). A larger one lets a physically unstable run grow over
    decades, so that its growth rate can be measured free of the bounded oscillation; the run
    is still reported as diverged where it passed the driver's limit."""
    extra = list(form.extra_columns)
    columns = list(COLUMNS) + extra + list(STRESS_COLUMNS)
    stress = form.root_stress
    writer = SeriesWriter(csv_path, meta, columns, enabled=enabled and csv_path is not None) \
        if csv_path else None
    rows: list[tuple] = []
    nsteps = max(int(round(case.t_end / case.dt)), 1)
    progress = Progress(nsteps, case.label(), enabled=enabled)

    def on_sample(t, tip, extras, q):
        s = stress(t, q) if stress is not None else (math.nan, math.nan)
        row = (t, *tip, *extras, float(np.max(s)), float(np.min(s)))
        rows.append(row)
        if writer is not None:
            writer.write(row)

    every = max(1, int(round(sample_dt / case.dt)))
    try:
        res = simulate(form, case.integrator, case.dt, case.t_end, sample_every=every,
                       on_sample=on_sample, progress=progress, limit=limit)
    finally:
        if writer is not None:
            writer.close()
    progress.close(f"{res.steps} steps")
    diverged = diagnose(form, case.integrator, case.dt, res) if res.diverged else None
    return CaseResult(case=case, columns=columns, data=np.array(rows, dtype=float),
                      steps=res.steps, wall_s=res.wall_s, diverged=diverged, dof=form.dof,
                      limit=divergence_limit(form))


def summarise(result: CaseResult, t_end: float, steady_tip: np.ndarray | None = None,
              growth_rate: float | None = None) -> dict:
    """What a study reports about one run read over the window [0, t_end].

    ``hann_mean``: the Hann-weighted mean deflection (what the run oscillates about), given only
    for runs that stayed bounded; ``measured_growth``: for a divergent run, the slope of
    log |tip - steady| over the samples where the deviation exceeds 100 times the equilibrium
    deflection (3 times when the run stopped at the driver's limit), where the unstable mode
    dominates, next to ``growth_rate`` (Re lambda_max). Everything else is read up to the
    divergence time."""
    case = result.case
    full = result.window(t_end)
    d = full[full[:, 0] <= (result.divergence_time() or np.inf)]
    t, tip = d[:, 0], d[:, 1:4]
    finite = np.all(np.isfinite(tip), axis=1)
    out = {"case": {**asdict(case), "t_end": t_end}, "name": case.name, "dof": result.dof,
           "t_reached_s": float(t[-1]) if t.size else 0.0,
           "final_mm": (1e3 * tip[-1]).tolist() if t.size else None,
           "peak_mm": (1e3 * np.nanmax(np.abs(tip[finite]), axis=0)).tolist()
           if finite.any() else None,
           "diverged": None, "hann_mean_mm": None, "measured_growth": None,
           "eigen_growth": growth_rate}
    dv, td = result.diverged, result.divergence_time()
    if dv is not None and td <= t_end + 0.5 * case.dt:
        detail = dv["detail"].split("; ", 1)
        out["diverged"] = {"time_s": td, "cause": dv["cause"],
                           "detail": f"deflection past {result.limit:.3g} m"
                           + (f"; {detail[1]}" if len(detail) > 1 else "")}
        if steady_tip is not None:
            ft = full[np.all(np.isfinite(full[:, 1:4]), axis=1)]
            dev = np.linalg.norm(ft[:, 1:4] - steady_tip, axis=1).max()
            far = dev > 1e3 * max(np.linalg.norm(steady_tip), 1e-12)
            out["measured_growth"] = deviation_growth(ft, steady_tip, 100.0 if far else 3.0)[0]
    elif t.size > 2:
        out["hann_mean_mm"] = (1e3 * hann_mean(t, tip)).tolist()
    if steady_tip is not None:
        out["steady_mm"] = (1e3 * np.asarray(steady_tip)).tolist()
    sig = d[:, result.columns.index(STRESS_COLUMNS[0]):]
    if np.isfinite(sig).any():
        out["sigma_root_max_MPa"] = float(np.nanmax(sig[:, 0]) / 1e6)
        out["sigma_root_min_MPa"] = float(np.nanmin(sig[:, 1]) / 1e6)
    if "drive_torque_Nm" in result.columns:
        tau = d[:, result.columns.index("drive_torque_Nm")]
        ok = np.isfinite(tau)
        out["torque_peak_Nm"] = float(np.max(np.abs(tau[ok]))) if ok.any() else None
        out["torque_final_Nm"] = float(tau[-1])
        out["torque_mean_Nm"] = float(hann_mean(t, tau)) if out["diverged"] is None \
            and t.size > 2 else None
    steps = int(round(min(t_end, full[-1, 0] if full.size else 0.0) / case.dt))
    out["steps"] = steps
    out["us_per_step"] = 1e6 * result.wall_s / max(result.steps, 1)
    out["wall_s"] = result.wall_s * steps / max(result.steps, 1)
    return out
