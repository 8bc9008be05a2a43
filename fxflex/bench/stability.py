"""``fxflex bench stability``: critical steps, long runs and hostile scenes (issue 7, part 4).

Writes ``stability.md`` (tables), ``stability.json`` (everything) and ``stability.png`` (the
long-run energies and the highest mode's growth) into the output folder.

1. **Critical step** per method and integrator, by bisection on the formulation itself, against
   the eigenvalue estimate. A trial at step h runs the scene twice in lockstep from the initial
   state, once with the state perturbed by ``PERTURBATION`` along the highest mode (found by power
   iteration on finite differences of ``acceleration``), and measures how the difference grows:
   the largest |dq| over the last edge window against the largest over the first (each edge
   window 2 % of the run and at least two periods of the highest mode). Central difference:
   ``CD_WINDOW_STEPS`` steps, unstable when the difference grows by more than ``CD_GROWTH``;
   estimate 2 / w_max and the damped one-mode root (:mod:`fxflex.time.step_stability`). AB2, which
   has no sharp limit: unstable when it grows by more than e over ``AB2_PERIODS`` periods of the
   highest mode (a window in the mode's own time scale, so that every method's trials take a
   few thousand steps; the growth is measured between the edge windows, 98 periods apart);
   estimates from the law w^4 h^3 / 4 - c / (2 rho) of NOTES.md and from AB2's exact root.
   Generalised-alpha (rho_inf 0.9), unconditionally stable on linear systems: its one-mode
   spectral radius is checked to stay <= 1 up to h w = 1e4 (it tends to rho_inf), and one trial
   at ``GA_STEP_FACTOR`` times CD's limit measures the push's growth (a decay; Newton solved to
   ``GA_TRIAL_TOL`` in both runs, so that their difference is dynamics, not iteration error).
2. **Long runs**: ``LONG_STEPS`` steps of the reduced and beam models with each integrator at the
   paper's step (ANCF-AB2 at the efficiency study's 0.02 us: AB2 at ANCF's 1.7 us is far past
   any limit), started with the same small push along the highest mode. Every 1/2000 of the run:
   the energy of the motion about the steady state in the rotating frame,
   H = 1/2 z'.M z' + 1/2 (z - z*).K (z - z*) with (M, K) of ``linearise()`` (for a damped
   gyroscopic system dH/dt = -(c/rho) z'.M z' <= 0, and H decays like exp(-c t / rho)), and the
   amplitude of the highest mode, whose growth rate is set against AB2's law and exact root.
3. **Hostile scenes** (``HOSTILE``): every method through the command line (``fxflex run --json
   --out``, the paper's integrator and step, 2 ms): completed (with the AB2 warning if its
   highest mode grew by more than e^10), or stopped with a diagnosis; the JSON and the CSV are
   checked for NaN.

``quick``: coarse meshes (``COARSE``), 2e4-step long runs, 0.5 ms hostile windows.
"""

from __future__ import annotations

import json
import math
import os
import time

import numpy as np

from fxflex.bench.common import machine, markdown_table, run_cli
from fxflex.formulation import (PAPER_AB_STEP, PAPER_INTEGRATION, BuildOptions, build,
                                implicit_step)
from fxflex.scene import METHODS, Scene, load_scene
from fxflex.time import make_scheme
from fxflex.time import step_stability as stability

__all__ = ["run", "HOSTILE", "COARSE", "top_vector", "growth_over", "critical_step_study",
           "long_run", "hostile_case", "INTEGRATORS"]

#: the scenes of the issue, as --set overrides of the base scene
HOSTILE = {
    "30000 rpm": ["rotation.rpm=30000"],
    "very thin section (Z sizes / 10)": ["geometry.root_z=0.006", "geometry.tip_z=0.004"],
    "very short section (Y sizes / 10)": ["geometry.root_y=0.012", "geometry.tip_y=0.008"],
    "very short beam (L = 0.2 m)": ["geometry.length=0.2"],
    "zero damping": ["damping.c=0"],
    "huge damping (c = 1e11)": ["damping.c=1e11"],
    "twist 0 deg": ["geometry.twist_deg=0"],
    "twist 180 deg": ["geometry.twist_deg=180"],
}
#: coarse meshes of the quick run and of the tests
COARSE = ["mesh.solid=[10,2,2]", "reduction.ffrf_modes=10", "reduction.gcms_modes=30"]
INTEGRATORS = ("cd", "ab2", "generalized-alpha")
#: generalized-alpha has no step limit: its trial runs at this multiple of CD's limit
GA_STEP_FACTOR = 10.0
PERTURBATION = 1e-9          # Euclidean norm of the push along the highest mode
#: Newton tolerance of the generalised-alpha trial: two runs 1e-9 apart differ by less than the
#: default 1e-5's iteration error on a nonlinear model (NEBB's push then "grew" 148-383x; 1e-9:
#: decays to 0.015)
GA_TRIAL_TOL = 1e-9
CD_WINDOW_STEPS, CD_GROWTH = 2000, 10.0
AB2_PERIODS, AB2_LOG_GROWTH = 100, 1.0
LONG_STEPS = 1_000_000
LONG_METHODS = ("ffrf", "gcms", "lebb", "nebb", "ancf")


def _dot(comm, a, b) -> float:
    value = float(np.dot(a, b))
    return comm.allreduce(value) if comm is not None and comm.size > 1 else value


def top_vector(form, iterations: int = 400, rtol: float = 1e-8, seed: int = 1
               ) -> tuple[np.ndarray, float, int]:
    """(x, w, iterations): the highest mode of the formulation at t = 0 by power iteration on
    J x = (a(q0 + delta x) - a(q0)) / delta ~ -M^-1 K x (finite differences of ``acceleration``
    with constrained coordinates held), x of unit Euclidean norm, w = sqrt(-x.Jx / x.x)."""
    comm = form.comm
    q0, v0 = form.initial_state()
    form.constrain(0.0, q0, v0)
    a0, a1 = np.empty_like(q0), np.empty_like(q0)
    form.acceleration(0.0, q0, v0, a0)
    local_max = float(np.max(np.abs(q0))) if q0.size else 0.0
    scale = max(comm.allreduce(local_max, op=_max_op()) if comm.size > 1 else local_max,
                1e-3 * form.scene.geometry.length)
    x = np.random.default_rng(seed + comm.rank).standard_normal(q0.size)
    qp, vp = np.empty_like(q0), np.empty_like(v0)
    lam_old, lam, it = None, 0.0, 0
    for it in range(1, iterations + 1):
        x /= math.sqrt(_dot(comm, x, x))
        delta = 1e-7 * scale
        np.multiply(x, delta, out=qp)
        qp += q0
        vp[:] = v0
        form.constrain(0.0, qp, vp)
        form.acceleration(0.0, qp, vp, a1)
        y = (a1 - a0) / delta
        lam = -_dot(comm, x, y)
        x = y
        if lam_old is not None and abs(lam - lam_old) <= rtol * abs(lam):
            break
        lam_old = lam
    x /= math.sqrt(_dot(comm, x, x))
    return x, math.sqrt(max(lam, 0.0)), it


def _max_op():
    from mpi4py import MPI
    return MPI.MAX


@np.errstate(over="ignore", invalid="ignore")     # an unstable trial overflows; it is caught
def growth_over(form, integrator: str, h: float, steps: int, x: np.ndarray, w: float,
                stop_at: float = 1e6) -> float:
    """Growth of a push along ``x`` over ``steps`` steps of size h: max |dq| over the last edge
    window / max |dq| over the first (module docstring); inf once it exceeds ``stop_at``."""
    comm = form.comm
    q1, v1 = form.initial_state()
    q2, v2 = q1.copy(), v1.copy()
    q2 += PERTURBATION * x
    options = {"tol": GA_TRIAL_TOL} if integrator == "generalized-alpha" else {}
    s1, s2 = make_scheme(integrator, **options), make_scheme(integrator, **options)
    s1.start(form, 0.0, h, q1, v1)
    s2.start(form, 0.0, h, q2, v2)
    edge = max(int(0.02 * steps), int(2 * 2 * math.pi / (w * h)) + 1, 2)
    e = np.empty_like(q1)
    early = late = 0.0
    for k in range(1, steps):
        np.subtract(q2, q1, out=e)
        size = math.sqrt(_dot(comm, e, e))
        if not math.isfinite(size) or size > stop_at * PERTURBATION:
            return math.inf
        if k <= edge:
            early = max(early, size)
        if k >= steps - edge:
            late = max(late, size)
        s1.step(form, k * h, h, q1, v1)
        s2.step(form, k * h, h, q2, v2)
    return late / early if early > 0 else math.inf


def _bisect(unstable, guess: float, rel: float) -> tuple[float, float, int]:
    """(largest stable, smallest unstable, trials): a bracket [0.7, 1.6] x ``guess`` (widened
    if needed; asymmetric, so that no trial falls on the guess itself), then bisection."""
    lo, hi, trials = 0.7 * guess, 1.6 * guess, 0
    while True:
        trials += 1
        if not unstable(lo):
            break
        lo, hi = 0.7 * lo, lo
    while True:
        trials += 1
        if unstable(hi):
            break
        lo, hi = hi, 1.6 * hi
    while hi - lo > rel * lo:
        mid = math.sqrt(lo * hi)
        trials += 1
        lo, hi = (lo, mid) if unstable(mid) else (mid, hi)
    return lo, hi, trials


def critical_step_study(form, integrator: str) -> dict:
    """Measured critical step of ``integrator`` on ``form`` and its estimates (module docstring)."""
    t0 = time.perf_counter()
    x, w_power, iterations = top_vector(form)
    w, d = stability.top_mode(form)
    row = {"method": form.method, "integrator": integrator, "dof": form.dof,
           "omega_max": w, "omega_power": w_power, "power_iterations": iterations,
           "c_rho": d}
    if integrator == "generalized-alpha":
        hw = np.logspace(-2, 4, 25)
        radius = max(stability.amplification(integrator, k / w, w, d) for k in hw)
        h = GA_STEP_FACTOR * stability.critical_step("cd", w, d)
        growth = growth_over(form, integrator, h, CD_WINDOW_STEPS, x, w)
        row.update(window=f"{CD_WINDOW_STEPS} steps at {GA_STEP_FACTOR:g} x CD's limit",
                   max_radius=radius, trial_step=h, trial_growth=growth,
                   seconds=time.perf_counter() - t0)
        return row
    if integrator == "cd":
        guess = stability.critical_step("cd", w, d)
        lo, hi, trials = _bisect(
            lambda h: growth_over(form, "cd", h, CD_WINDOW_STEPS, x, w) > CD_GROWTH, guess, 1e-3)
        row.update(window=f"{CD_WINDOW_STEPS} steps, growth > {CD_GROWTH:g}",
                   estimate_2_over_w=2.0 / w, estimate_root=guess)
    else:
        window = AB2_PERIODS * 2 * math.pi / w
        span = 0.98 * window                        # between the edge windows
        law = stability.ab2_law_step(w, span, AB2_LOG_GROWTH, d)
        guess = stability.critical_step("ab2", w, d, window=span, log_growth=AB2_LOG_GROWTH)
        lo, hi, trials = _bisect(
            lambda h: growth_over(form, "ab2", h, int(round(window / h)), x, w)
            > math.exp(AB2_LOG_GROWTH), guess, 2e-3)
        row.update(window=f"{AB2_PERIODS} periods = {window * 1e3:.4g} ms, growth > e",
                   window_s=window, estimate_law=law, estimate_root=guess)
    row.update(measured_lo=lo, measured_hi=hi, measured=math.sqrt(lo * hi), trials=trials,
               ratio_to_root=math.sqrt(lo * hi) / row["estimate_root"],
               seconds=time.perf_counter() - t0)
    return row


def long_step(method: str, integrator: str, rpm: float = 1000.0) -> float:
    """The paper's step of the method for both explicit integrators, but AB2 for ANCF at
    0.02 us; generalized-alpha's default step (``implicit_step``)."""
    if integrator == "generalized-alpha":
        return implicit_step(method, rpm)
    paper_integrator, paper_dt = PAPER_INTEGRATION[method]
    if integrator == "ab2" and paper_integrator == "cd":
        return PAPER_AB_STEP
    return paper_dt


@np.errstate(over="ignore", invalid="ignore")     # a diverging AB2 run; it is caught
def long_run(form, integrator: str, h: float, steps: int, records: int = 2000) -> dict:
    """Deviation energy and highest-mode amplitude over ``steps`` steps (module docstring)."""
    import scipy.linalg as la

    t0 = time.perf_counter()
    lin = form.linearise()
    M, K = lin.M, 0.5 * (lin.K + lin.K.T)
    zs, _ = form.rotating_state(0.0, form.steady_state().q, np.zeros_like(form.steady_state().q))
    n = K.shape[0]
    lam, vec = la.eigh(K, M, subset_by_index=[n - 1, n - 1])
    w_top, x_top = math.sqrt(lam[0]), vec[:, 0]          # M-normalised
    Mx = M @ x_top
    push, w_power, _ = top_vector(form)
    d = form.scene.damping.c / form.scene.material.rho
    q, v = form.initial_state()
    q += PERTURBATION * push
    scheme = make_scheme(integrator)
    scheme.start(form, 0.0, h, q, v)
    every = max(steps // records, 1)
    ts, energy, amp = [], [], []
    stopped = None
    for k in range(1, steps + 1):
        if k % every == 0 or k == steps:
            t = k * h
            z, zd = form.rotating_state(t, q, v)
            dz = z - zs
            H = 0.5 * zd @ M @ zd + 0.5 * dz @ K @ dz
            a = math.hypot(Mx @ dz, (Mx @ zd) / w_top)
            if not (math.isfinite(H) and math.isfinite(a)) or (energy and H > 1e8 * energy[0]):
                stopped = t
                break
            ts.append(t)
            energy.append(H)
            amp.append(a)
        if k < steps:
            scheme.step(form, k * h, h, q, v)
    wall = time.perf_counter() - t0
    ts, energy, amp = np.array(ts), np.array(energy), np.array(amp)
    ramp = form.scene.load.ramp_time
    after = ts >= 2 * ramp
    row = {"method": form.method, "integrator": integrator, "dt_s": h, "steps": steps,
           "t_end_s": steps * h, "stopped_at_s": stopped, "wall_s": wall,
           "omega_top": w_top, "omega_power": w_power, "c_rho": d,
           "t": ts.tolist(), "energy": energy.tolist(), "amplitude": amp.tolist()}
    if after.sum() >= 2:
        H0 = energy[after][0]
        span = ts[after][-1] - ts[after][0]
        row.update(H_ref=H0, H_max_over_ref=float(energy[after].max() / H0),
                   H_end_over_ref=float(energy[after][-1] / H0),
                   H_decay_expected=math.exp(-d * span))
    # growth of the highest mode: fit ln(amplitude) after the ramp
    if after.sum() >= 10 and np.all(amp[after] > 0):
        slope = float(np.polyfit(ts[after], np.log(amp[after]), 1)[0])
        row["top_growth_measured"] = slope
    row["top_growth_root"] = stability.growth_rate(integrator, h, w_top, d)
    if integrator == "ab2":
        row["top_growth_law"] = stability.ab2_law_rate(w_top, h, d)
    return row


def hostile_case(base: Scene, name: str, method: str, out_dir: str, t_end: float) -> dict:
    """One method on one hostile scene through the command line; checks the outputs for NaN."""
    scene = load_scene(overrides=HOSTILE[name], base=base)
    csv = os.path.join(out_dir, f"{method}-{name.split(' (')[0].replace(' ', '_')}.csv")
    res = run_cli(["run", "--method", method, "--t-end", str(t_end), "--out", csv], scene)
    row = {"scene": name, "method": method, "wall_s": res.get("wall_s")}
    if "error" in res:
        row.update(outcome="rejected", detail=res["error"])
        return row
    text = open(csv).read() if os.path.exists(csv) else ""
    body = [ln for ln in text.splitlines() if ln and not ln.startswith("#")][1:]
    nan_csv = any(not all(math.isfinite(float(x)) for x in ln.split(",")) for ln in body)
    nan_json = "NaN" in json.dumps(res) or any(v is None for v in res["tip_mm"].values())
    div = res["diverged"]
    warned = bool(res.get("warnings"))
    row.update(outcome=("completed" if div is None else div["cause"])
               + (" (warning)" if warned else ""), warnings=res.get("warnings", []),
               t_s=res["t_s"],
               steps=res["steps"], tip_mm=res["tip_mm"], rows=len(body),
               nan_in_output=bool(nan_csv or nan_json),
               detail=div["detail"] if div else ("; ".join(res["warnings"]) if warned else None),
               growth_rate=None if div is None else div.get("growth_rate"),
               dt_limit_s=None if div is None else div.get("dt_limit_s"))
    return row


def _fmt(x, spec=".4g"):
    return "-" if x is None else format(x, spec)


def render(d: dict) -> str:
    lines = ["# Stability: critical steps, long runs, hostile scenes (issue 7)", "",
             f"{'QUICK smoke run (coarse meshes); ' if d['quick'] else ''}machine: "
             f"{d['machine']['cpu']}, {d['machine']['cores']} cores, load average "
             f"{d['load_average'][0]:.2f} at the start, {d['load_average'][1]:.2f} at the end; "
             f"scene {d['scene_hash']} (1000 rpm, c = 1000 unless stated), meshes "
             f"{d['meshes']}.", "", "## Critical steps", "",
             f"Bisection on the formulation (module docstring): CD unstable when a push along "
             f"the highest mode grows by more than {CD_GROWTH:g} in {CD_WINDOW_STEPS} steps; AB2 "
             f"when it grows by more than e over {AB2_PERIODS} periods of the highest mode "
             f"(measured between edge windows 98 periods apart). w_max: largest undamped "
             f"frequency of the linearisation (TLF: of the clamped body, SLEPc); power: the same "
             f"from the power iteration on the time loop's own acceleration.", ""]
    rows = []
    for r in d["critical"]:
        if r["integrator"] == "generalized-alpha":
            continue
        est = ([f"{r['estimate_2_over_w']:.4g}", f"{r['estimate_root']:.4g}"]
               if r["integrator"] == "cd" else
               [f"{r['estimate_law']:.4g} (law)", f"{r['estimate_root']:.4g}"])
        rows.append([r["method"], r["integrator"], r["dof"], f"{r['omega_max']:.5g}",
                     f"{r['omega_power']:.5g}", *est,
                     f"{r['measured_lo']:.4g} - {r['measured_hi']:.4g}",
                     f"{r['ratio_to_root']:.4f}", r["trials"], f"{r['seconds']:.0f}"])
    lines.append(markdown_table(
        ["method", "integrator", "dof", "w_max rad/s", "w power rad/s",
         "estimate s (CD: 2/w_max; AB2: law)", "one-mode root s", "measured s", "measured / root",
         "trials", "s"], rows))
    ga = [r for r in d["critical"] if r["integrator"] == "generalized-alpha"]
    if ga:
        lines += ["", f"Generalised-alpha (rho_inf 0.9) has no step limit: its one-mode spectral "
                  f"radius stays <= 1 for h w from 0.01 to 1e4 (tending to rho_inf), and a push "
                  f"along the highest mode over {CD_WINDOW_STEPS} steps at "
                  f"{GA_STEP_FACTOR:g} x CD's limit does not grow:", ""]
        lines.append(markdown_table(
            ["method", "max one-mode radius", "step s", "h w_max", "growth of the push", "s"],
            [[r["method"], f"{r['max_radius']:.6f}", f"{r['trial_step']:.3g}",
              f"{r['trial_step'] * r['omega_max']:.3g}", f"{r['trial_growth']:.3g}",
              f"{r['seconds']:.0f}"] for r in ga]))
    lines += ["", f"## Long runs ({d['long_steps']} steps)", "",
              "H: energy of the motion about the steady state (rotating frame, linearisation), "
              "relative to its value at t = 2 x ramp; physically it decays like exp(-c t / rho). "
              "Top mode: growth rate (1/s) of the highest mode's amplitude after the ramp, "
              "measured, from the scheme's exact one-mode root, and from the law "
              "w^4 h^3/4 - c/(2 rho).", ""]
    rows = []
    for r in d["long"]:
        rows.append([r["method"], r["integrator"], f"{r['dt_s'] * 1e6:.3g}",
                     _fmt(r["stopped_at_s"], ".4g") if r["stopped_at_s"] else
                     f"no ({r['t_end_s']:.3g} s)",
                     _fmt(r.get("H_max_over_ref"), ".6f"), _fmt(r.get("H_end_over_ref"), ".6f"),
                     _fmt(r.get("H_decay_expected"), ".6f"), f"{r['omega_top']:.4g}",
                     _fmt(r.get("top_growth_measured"), ".4g"), _fmt(r.get("top_growth_root")),
                     _fmt(r.get("top_growth_law")), f"{r['wall_s']:.0f}"])
    lines.append(markdown_table(
        ["method", "integrator", "dt us", "diverged at s", "max H / H_ref", "end H / H_ref",
         "exp(-c t/rho)", "w top rad/s", "top growth measured", "root", "law", "wall s"], rows))
    lines += ["", f"## Hostile scenes ({d['hostile_t_end'] * 1e3:g} ms, paper integrator and "
              f"step)", "", "Outcome: completed (\"(warning)\": AB2 grew its highest mode by more "
              "than e^10), or the cause of the early stop; every CSV and JSON output checked "
              "for NaN.", ""]
    rows = []
    for r in d["hostile"]:
        tip = r.get("tip_mm")
        rows.append([r["scene"], r["method"], r["outcome"],
                     _fmt(r.get("t_s"), ".3g"),
                     " / ".join(f"{v:.4g}" for v in tip.values()) if tip else "-",
                     _fmt(r.get("growth_rate")), _fmt(r.get("dt_limit_s")),
                     "NaN!" if r.get("nan_in_output") else "none"])
    lines.append(markdown_table(["scene", "method", "outcome", "t reached s",
                                 "tip mm (long / orth / load)", "eigenvalue Re 1/s",
                                 "dt limit s", "NaN in output"], rows))
    lines += ["", "Details of the stops:", ""]
    lines += [f"- {r['scene']}, {r['method']}: {r['detail']}" for r in d["hostile"]
              if r.get("detail")]
    return "\n".join(lines) + "\n"


def plot(d: dict, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.5))
    for r in d["long"]:
        t, H = np.array(r["t"]), np.array(r["energy"])
        if len(t) and r.get("H_ref"):
            ax1.semilogy(t, H / r["H_ref"], label=f"{r['method']} {r['integrator']}",
                         ls={"cd": "-", "ab2": "--"}.get(r["integrator"], ":"))
        a = np.array(r["amplitude"])
        if len(t) and np.all(a > 0):
            line, = ax2.semilogy(t, a / a[0], ls={"cd": "-", "ab2": "--"}.get(r["integrator"],
                                                                               "-."),
                                 label=f"{r['method']} {r['integrator']}")
            if r["integrator"] == "ab2":
                ax2.semilogy(t, np.exp(r["top_growth_root"] * (t - t[0])), ls=":",
                             color=line.get_color())
    ax1.set(xlabel="t (s)", ylabel="H / H(2 ramp)", title="energy about the steady state",
            xscale="log")
    ax2.set_xscale("log")
    ax2.set(xlabel="t (s)", ylabel="amplitude / initial",
            title="highest mode (dotted: AB2 exact root)")
    ax2.set_ylim(1e-3, 1e12)
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run(scene: Scene, out_dir: str, comm, quick: bool = False) -> dict:
    load0 = os.getloadavg()[0]
    base = load_scene(overrides=COARSE, base=scene) if quick else scene
    critical = []
    for method in METHODS:
        # need_steady=False: TLF, whose step limit is its clamped body's top frequency, builds
        # its time-loop operators now; the other methods do not read it
        form = build(method, base, comm, BuildOptions(need_steady=False))
        for integrator in INTEGRATORS:
            critical.append(critical_step_study(form, integrator))
            r = critical[-1]
            _progress(comm, f"critical {method} {integrator}: "
                            + (f"{r['measured']:.4g} s" if "measured" in r else
                               f"growth {r['trial_growth']:.3g} at {r['trial_step']:.3g} s"))
    long_steps = 20_000 if quick else LONG_STEPS
    long = []
    for method in LONG_METHODS:
        form = build(method, base, comm)
        for integrator in INTEGRATORS:
            long.append(long_run(form, integrator,
                                 long_step(method, integrator, base.rotation.rpm), long_steps))
            _progress(comm, f"long {method} {integrator}: {long[-1]['wall_s']:.0f} s")
    hostile_t = 0.5e-3 if quick else 2e-3
    hostile = []
    host_dir = os.path.join(out_dir, "hostile")
    if comm.rank == 0:
        os.makedirs(host_dir, exist_ok=True)
        for name in HOSTILE:
            for method in METHODS:
                hostile.append(hostile_case(base, name, method, host_dir, hostile_t))
                _progress(comm, f"hostile {name} {method}: {hostile[-1]['outcome']}")
    result = {"quick": quick, "machine": machine(), "scene_hash": base.hash,
              "meshes": f"solid {list(base.mesh.solid)}, beam {base.mesh.beam_elements}, FFRF "
                        f"{base.reduction.ffrf_modes} modes, GCMS {base.reduction.gcms_modes}",
              "load_average": [load0, os.getloadavg()[0]], "critical": critical,
              "long_steps": long_steps, "long": long, "hostile_t_end": hostile_t,
              "hostile": hostile}
    if comm.rank == 0:
        with open(os.path.join(out_dir, "stability.md"), "w") as fh:
            fh.write(render(result))
        with open(os.path.join(out_dir, "stability.json"), "w") as fh:
            json.dump(result, fh, indent=1, default=float)
        plot(result, os.path.join(out_dir, "stability.png"))
    bad = [r for r in hostile if r.get("nan_in_output")]
    worst = max(abs(r["ratio_to_root"] - 1) for r in critical if "ratio_to_root" in r)
    result["summary"] = "\n".join(
        [f"bench stability: {os.path.join(out_dir, 'stability.md')}",
         f"  critical steps: measured within {100 * worst:.2f} % of the one-mode root"]
        + [f"  long {r['method']} {r['integrator']}: "
           + (f"diverged at {r['stopped_at_s']:.4g} s" if r["stopped_at_s"] else
              f"max H/H_ref {r.get('H_max_over_ref', float('nan')):.4f}") for r in long]
        + [f"  hostile: {len(hostile)} runs, {len(bad)} with NaN in an output"])
    return result


def _progress(comm, text: str) -> None:
    if comm.rank == 0:
        import sys
        sys.stderr.write(f"  {text}\n")
        sys.stderr.flush()
