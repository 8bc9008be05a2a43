"""``fxflex bench reduced``: FFRF and GCMS on the default scene (issue 3).

Reports preprocessing (mesh, assembly, eigenmodes, invariants / global modes) and the time of
1e4 AB2 steps at dt = 0.02 us (the paper's Table 3 set-up), and the accuracy studies: FFRF steady
state against the full-order linear equilibrium for 10/30/60 modes, FFRF against GCMS over the
first 5 ms at 1000 rpm, the transient mean against the steady state, the 10000 rpm divergence
(measured growth against the eigenvalue), the FFRF-AB step-size study of Fig. 5 with the AB2
growth law, and the GCMS Gram cut. Tables go to ``reduced.md`` in the output folder.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time

import numpy as np

from fxflex import cache
from fxflex.analysis.signals import hann_mean
from fxflex.numerics.growth import growth_fit
from fxflex.scene import Scene
from fxflex.solid.family import ReducedFamily
from fxflex.solid.ffrf import FFRF
from fxflex.solid.gcms import GCMS

__all__ = ["ReducedFamily", "hann_mean", "growth_fit", "run"]

COMPONENTS = ("longitudinal", "orthogonal", "load")


def _progress(comm, text: str) -> None:
    """Progress on stderr (stdout carries the JSON with --json), rank 0 only."""
    if comm.rank == 0:
        print(text, file=sys.stderr, flush=True)


def speed(scene: Scene, comm, steps: int = 10_000, dt: float = 0.02e-6, repeats: int = 3
          ) -> list[dict]:
    """Preprocessing of FFRF and GCMS each built from nothing, and the best of ``repeats`` runs
    of ``steps`` AB2 steps through the generic driver (tip checked every 100 steps)."""
    from fxflex.time import simulate

    rows = []
    for cls in (FFRF, GCMS):
        t0 = time.perf_counter()
        with cache.bypass("modes", "reduced"):          # from nothing: no eigenmodes read
            form = cls(scene, comm)
        pre = time.perf_counter() - t0
        walls = [simulate(form, "ab2", dt, steps * dt, sample_every=steps).wall_s
                 for _ in range(repeats)]
        rows.append({"method": form.method, "dof": form.dof, "preprocess_s": pre,
                     "preprocess_detail_s": dict(form.timings),
                     "mesh_generated": bool(form.model.solid_mesh.generated),
                     "steps": steps, "dt_s": dt, "solve_s": min(walls), "solve_all_s": walls,
                     "us_per_step": 1e6 * min(walls) / steps})
    return rows


def steady_table(family: ReducedFamily, rpms=(1000.0, 5000.0), counts=(10, 30, 60)) -> list[dict]:
    """FFRF steady state against the full-order linear equilibrium (issue 3)."""
    from fxflex.solid.small_strain import linear_steady

    rows = []
    for rpm in rpms:
        full = linear_steady(family.model, rpm * math.pi / 30).tip
        for m in counts:
            tip = family.build("ffrf", f"rotation.rpm={rpm}",
                               f"reduction.ffrf_modes={m}").steady_state().tip
            rows.append({"rpm": rpm, "modes": m, "tip_mm": tip * 1e3, "full_mm": full * 1e3,
                         "rel_diff": np.abs(tip - full) / np.abs(full)})
        g = family.build("gcms", f"rotation.rpm={rpm}")
        tip = g.steady_state().tip
        rows.append({"rpm": rpm, "modes": f"gcms {g.dof}", "tip_mm": tip * 1e3,
                     "full_mm": full * 1e3, "rel_diff": np.abs(tip - full) / np.abs(full)})
    return rows


def history(form, dt: float, t_end: float, sample_dt: float, **kw) -> tuple[np.ndarray, object]:
    from fxflex.time import simulate

    res = simulate(form, "ab2", dt, t_end, sample_every=max(1, int(round(sample_dt / dt))),
                   keep_history=True, **kw)
    return np.array(res.history), res


def compare_ffrf_gcms(family: ReducedFamily, t_end: float) -> dict:
    """1000 rpm, c3, paper steps (0.5 and 0.3 us), compared every 1.5 us in the rotating frame."""
    a, _ = history(family.build("ffrf"), 0.5e-6, t_end, 1.5e-6)
    b, _ = history(family.build("gcms"), 0.3e-6, t_end, 1.5e-6)
    _, ia, ib = np.intersect1d(a[:, 0].round(12), b[:, 0].round(12), return_indices=True)
    a, b = a[ia], b[ib]
    peak = np.abs(a[:, 1:]).max(axis=0)
    return {"t_end_s": t_end, "samples": len(ia), "peak": peak,
            "max_diff_over_peak": np.abs(a[:, 1:] - b[:, 1:]).max(axis=0) / peak}


def mean_vs_steady(family: ReducedFamily, method: str, dt: float, t_end: float) -> dict:
    form = family.build(method)
    h, res = history(form, dt, t_end, 1e-5)
    st = form.steady_state().tip
    return {"method": method, "dt_s": dt, "t_end_s": t_end, "steady_mm": st * 1e3,
            "hann_mean_rel": np.abs(hann_mean(h[:, 0], h[:, 1:4]) - st) / np.abs(st),
            "plain_mean_rel": np.abs(h[:, 1:4].mean(axis=0) - st) / np.abs(st),
            "peak_over_steady": np.abs(h[:, 1:4]).max(axis=0) / np.abs(st),
            "wall_s": res.wall_s}


def divergence(family: ReducedFamily, method: str, dt: float, rpm: float = 10000.0) -> dict:
    """Time to the divergence limit, and the growth of the deviation from the (unstable)
    equilibrium measured while it is 100 times the equilibrium deflection and more."""
    from fxflex.time import deviation_growth, diagnose

    form = family.build(method, f"rotation.rpm={rpm}")
    _, res = history(form, dt, 0.05, 1e-5)
    h, _ = history(form, dt, 0.05, 1e-5, limit=100.0)
    measured, samples = deviation_growth(h, form.steady_state().tip)
    rate, freq = form.growth_rate()
    return {"method": method, "rpm": rpm, "dt_s": dt,
            "diverged_at_s": res.diverged["time_s"] if res.diverged else None,
            "cause": diagnose(form, "ab2", dt, res)["cause"] if res.diverged else None,
            "measured_growth": measured if samples > 10 else None,
            "eigenvalue_growth": rate, "eigenvalue_freq_hz": freq / (2 * math.pi)}


def step_study(family: ReducedFamily, method: str, dts, t_end: float, ref_dt: float,
               visible: float = 0.1) -> list[dict]:
    """The paper's Fig. 5 for ``method`` at 1000 rpm, c3: each step against ``ref_dt`` (max
    difference over the window relative to the reference peak, per component), whether the run
    diverged or visibly left the reference (difference > ``visible`` of the peak), and the AB2
    growth rates: predicted by the principal root and by the law w^4 h^3 / 4 of NOTES.md, and
    measured on the coordinate of the fastest-growing eigenvector."""
    import scipy.linalg as la

    from fxflex.time import AB2

    form = family.build(method)
    ref, _ = history(form, ref_dt, t_end, 5e-6)
    peak = np.abs(ref[:, 1:4]).max(axis=0)
    n = form.dof
    lin = form.linearise()
    M, C, K = lin.M, lin.C, lin.K
    MK, MC = np.linalg.solve(M, K), np.linalg.solve(M, C)    # M = I but for a tip director
    lam, left = la.eig(np.block([[np.zeros((n, n)), np.eye(n)], [-MK, -MC]]), left=True,
                       right=False)
    rows = []
    for dt in dts:
        h, res = history(form, dt, t_end, 5e-6)
        ok = np.isfinite(h[:, 1:4]).all(axis=1)
        diff = np.array([np.abs(np.interp(ref[:, 0], h[ok, 0], h[ok, 1 + k]) - ref[:, 1 + k])
                         .max() / peak[k] for k in range(3)]) if ok.sum() > 1 else None
        predicted, wk = form.ab2_growth_rate(dt)
        row = {"dt_s": dt, "h_wmax": dt * form.omega_max(), "max_diff_over_peak": diff,
               "diverged_at_s": res.diverged["time_s"] if res.diverged else None,
               "visible": bool(res.diverged) or bool(diff is not None and diff.max() > visible),
               "ab2_root_growth": predicted, "ab2_law_growth": wk**4 * dt**3 / 4,
               "growth_over_window": predicted * t_end, "measured_growth": None}
        if predicted * t_end > 12:                # the spurious mode dominates late on
            k = int(np.argmin(np.abs(np.abs(lam) - wk)))
            q, v = form.initial_state()
            scheme = AB2()
            scheme.start(form, 0.0, dt, q, v)
            ts, amp = [], []
            for i in range(1, int(round(t_end / dt))):
                scheme.step(form, i * dt, dt, q, v)
                a = abs(left[:n, k].conj() @ q + left[n:, k].conj() @ v)
                if not math.isfinite(a) or a > 1e250:
                    break
                ts.append((i + 1) * dt)
                amp.append(a)
            ts, amp = np.array(ts), np.array(amp)
            late = ts > 0.5 * ts[-1]
            row["measured_growth"] = growth_fit(ts[late], amp[late])
        rows.append(row)
    return rows


def omega_for_blowup(dt: float, window: float, log_growth: float = 20.0) -> float:
    """Circular frequency of an undamped mode that AB2 at step dt amplifies by exp(log_growth)
    within ``window`` (principal root; bisection on w)."""
    from fxflex.numerics.growth import ab2_root

    lo, hi = 1.0, 10.0 / dt
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        grows = math.log(float(ab2_root(np.array([1j * mid * dt]))[0])) / dt * window
        lo, hi = (mid, hi) if grows < log_growth else (lo, mid)
    return lo


def gram_study(family: ReducedFamily, tols, window: float = 0.01) -> list[dict]:
    """Retained global modes, highest frequency, AB2 step that keeps the fastest mode's growth
    over ``window`` below e (from the principal root), and the steady state, per Gram cut."""
    from fxflex.solid.small_strain import linear_steady

    full = linear_steady(family.model).tip
    rows = []
    for tol in tols:
        g = family.build("gcms", f"reduction.gcms_gram_tol={tol}")
        lo, hi = 1e-9, 5e-6
        for _ in range(60):                      # bisection on ln(growth) = rate * window = 1
            mid = math.sqrt(lo * hi)
            lo, hi = (mid, hi) if g.ab2_growth_rate(mid)[0] * window < 1 else (lo, mid)
        tip = g.steady_state().tip
        rows.append({"tol": tol, "kept": g.dof, "min_kept_rel_norm": float(np.sqrt(
                         g.gm.gram[g.gm.kept].min() / g.gm.gram.max())),
                     "omega_max": g.omega_max(), "dt_e_fold_s": lo,
                     "growth_at_0.3us_over_window": g.ab2_growth_rate(0.3e-6)[0] * window,
                     "tip_mm": tip * 1e3, "rel_diff_full": np.abs(tip - full) / np.abs(full)})
    return rows


def _fmt(x, spec=".3g"):
    if x is None:
        return "-"
    if isinstance(x, (list, tuple, np.ndarray)):
        return " / ".join(format(float(v), spec) for v in x)
    return format(x, spec) if isinstance(x, (float, np.floating)) else str(x)


def render(d: dict) -> str:
    """The Markdown report of :func:`run`'s results (JSON-able dict)."""
    spd, steady, cmp_, means, div = d["speed"], d["steady"], d["ffrf_vs_gcms"], d["means"], \
        d["divergence"]
    window, f = d["window_s"], d["frequencies_hz"]
    first_visible = {name: next((r["dt_s"] for r in d[f"steps_{name}"] if r["visible"]), None)
                     for name in ("ffrf", "gcms")}
    lines = ["# FFRF and GCMS: benchmark (issue 3)", "",
             f"{'QUICK smoke run (20x4x2 mesh, short windows); ' if d['quick'] else ''}"
             f"mesh {d['mesh']}; machine: {d['machine']}, {d['ranks']} rank(s), load average "
             f"{d['load_average_start']:.2f} at the start.", "",
             "## Speed (1e4 AB2 steps at dt = 0.02 us, paper Table 3 set-up; best of repeats)", "",
             "| method | dof | preprocess s | mesh / assemble / eigenmodes / projections s | "
             "1e4 steps s | us/step |", "|---|---|---|---|---|---|"]
    for r in spd:
        pd = r["preprocess_detail_s"]
        proj = pd.get("invariants", pd.get("global_modes", 0.0))
        lines.append(f"| {r['method']} | {r['dof']} | {r['preprocess_s']:.2f} | "
                     f"{pd.get('mesh', 0):.2f} / {pd.get('assemble', 0):.2f} / "
                     f"{pd.get('eigenmodes', 0):.2f} / {proj:.2f} | {r['solve_s']:.3f} | "
                     f"{r['us_per_step']:.1f} |")
    lines += ["", f"Mesh read from the .msh cache: "
              f"{'no (generated)' if spd[0]['mesh_generated'] else 'yes'}.", "",
              f"Clamped modes: f1 = {f[0]:.2f} Hz, f2 = {f[1]:.2f} Hz, f30 = {f[29]:.0f} Hz; "
              f"highest |lambda| of the linearised system at 1000 rpm: FFRF "
              f"{d['omega_max']['ffrf']:.4g} rad/s, GCMS {d['omega_max']['gcms']:.4g} rad/s.",
              "", "## Steady state against the full-order linear equilibrium", "",
              "| rpm | modes | tip mm (long / orth / load) | full order mm | relative difference |",
              "|---|---|---|---|---|"]
    for r in steady:
        lines.append(f"| {r['rpm']:.0f} | {r['modes']} | {_fmt(r['tip_mm'], '.6f')} | "
                     f"{_fmt(r['full_mm'], '.6f')} | {_fmt(r['rel_diff'], '.2e')} |")
    lines += ["", "## FFRF against GCMS, 1000 rpm, c3, first 5 ms (rotating frame)", "",
              f"max |FFRF - GCMS| / peak (long / orth / load / drive torque): "
              f"{_fmt(cmp_['max_diff_over_peak'], '.2e')} over {cmp_['samples']} samples.", "",
              "## Transient mean against the steady state, 1000 rpm", "",
              "| method | dt us | window ms | Hann-weighted mean rel. diff | plain mean rel. diff "
              "| peak / steady |", "|---|---|---|---|---|---|"]
    for r in means:
        lines.append(f"| {r['method']} | {r['dt_s'] * 1e6:g} | {r['t_end_s'] * 1e3:g} | "
                     f"{_fmt(r['hann_mean_rel'], '.1e')} | {_fmt(r['plain_mean_rel'], '.1e')} | "
                     f"{_fmt(r['peak_over_steady'], '.2f')} |")
    lines += ["", "## 10000 rpm", "",
              "| method | dt us | diverged at ms | cause | measured growth 1/s | eigenvalue 1/s |",
              "|---|---|---|---|---|---|"]
    for r in div:
        at = r["diverged_at_s"]
        lines.append(f"| {r['method']} | {r['dt_s'] * 1e6:g} | "
                     f"{'-' if at is None else f'{at * 1e3:.2f}'} | {r['cause']} | "
                     f"{_fmt(r['measured_growth'], '.2f')} | {r['eigenvalue_growth']:.2f} |")
    for name, rows, ref in (("FFRF", d["steps_ffrf"], 0.25), ("GCMS", d["steps_gcms"], 0.15)):
        lines += ["", f"## {name}-AB step-size study (Fig. 5), 1000 rpm, c3, "
                      f"{window * 1e3:g} ms against dt = {ref} us", "",
                  "| dt us | h w_max | max diff / peak (long / orth / load) | diverged at ms | "
                  "AB2 growth 1/s: principal root / w^4 h^3/4 / measured | ln growth over window |",
                  "|---|---|---|---|---|---|"]
        for r in rows:
            at = r["diverged_at_s"]
            lines.append(f"| {r['dt_s'] * 1e6:g} | {r['h_wmax']:.3f} | "
                         f"{_fmt(r['max_diff_over_peak'], '.1e')} | "
                         f"{'-' if at is None else f'{at * 1e3:.3f}'} | "
                         f"{_fmt(r['ab2_root_growth'], '.4g')} / {_fmt(r['ab2_law_growth'], '.4g')}"
                         f" / {_fmt(r['measured_growth'], '.4g')} | "
                         f"{r['growth_over_window']:.3g} |")
        lines.append(f"\nFirst step that diverges or leaves the reference by more than 10 % of the "
                     f"peak within the window: {_fmt(first_visible[name.lower()])} s.")
    w06 = d["blowup_omega_0.6us"]
    lines.append(f"\nThe paper's FFRF-AB blow-up at 0.6 us needs a mode that AB2 amplifies by e^20 "
                 f"within the window: w >= {w06:.3g} rad/s ({w06 / (2 * math.pi):.3g} Hz). Our "
                 f"FFRF reaches {d['omega_max']['ffrf']:.3g} rad/s, our GCMS "
                 f"{d['omega_max']['gcms']:.3g} rad/s.")
    lines += ["", "## GCMS Gram cut (relative M-norm of the M-orthogonalised global modes)", "",
              "| gcms_gram_tol | kept | smallest kept rel. norm | w_max rad/s | "
              "dt for growth e in 10 ms, us | ln growth at 0.3 us in 10 ms | "
              "steady rel. diff to full order |", "|---|---|---|---|---|---|---|"]
    for r in d["gram"]:
        lines.append(f"| {r['tol']:g} | {r['kept']} | {r['min_kept_rel_norm']:.2e} | "
                     f"{r['omega_max']:.4g} | {r['dt_e_fold_s'] * 1e6:.3f} | "
                     f"{r['growth_at_0.3us_over_window']:.3g} | {_fmt(r['rel_diff_full'], '.2e')} |")
    return "\n".join(lines) + "\n"


def run(scene: Scene, out_dir: str, comm, quick: bool = False) -> dict:
    """All of the above on ``scene`` (the default scene unless overridden; ``quick``: a 20x4x2
    mesh and short windows, a smoke run)."""
    import platform

    from fxflex.io.payload import jsonable

    if quick:
        scene = scene.replace(**{"mesh.solid": (20, 4, 2)})
    base = scene.replace(**{"rotation.rpm": 1000.0, "rotation.profile": "constant",
                            "damping.c": 1000.0, "damping.model": "relative"})
    say = lambda text: _progress(comm, text)      # noqa: E731
    load0 = os.getloadavg()[0]
    say("bench reduced: speed")
    spd = speed(base, comm, steps=10_000, repeats=1 if quick else 3)
    family = ReducedFamily(base, comm, count=60)
    say("bench reduced: steady states")
    steady = steady_table(family)
    say("bench reduced: FFRF vs GCMS transient")
    cmp_ = compare_ffrf_gcms(family, 0.005)
    say("bench reduced: transient means")
    # GCMS at its paper step 0.3 us amplifies its fastest mode (5e5 rad/s) by e^5 every 10 ms:
    # invisible over the paper's windows, not over 100 ms; 0.1 us is the paper's damping-study step
    means = [mean_vs_steady(family, "ffrf", 0.5e-6, 0.05 if quick else 0.2),
             mean_vs_steady(family, "gcms", 0.1e-6, 0.02 if quick else 0.1)]
    say("bench reduced: 10000 rpm")
    div = [divergence(family, "ffrf", 0.5e-6), divergence(family, "gcms", 0.3e-6)]
    say("bench reduced: step-size studies")
    window = 0.005 if quick else 0.01
    steps_ffrf = step_study(family, "ffrf", (0.5e-6, 0.6e-6, 1e-6, 2e-6, 3e-6, 4e-6, 5e-6, 6e-6,
                                             8e-6), window, 0.25e-6)
    steps_gcms = step_study(family, "gcms", (0.3e-6, 0.4e-6, 0.5e-6, 0.6e-6, 0.8e-6), window,
                            0.15e-6)
    say("bench reduced: Gram cut")
    gram = gram_study(family, (1e-8, 1e-6, 1e-4, 3e-4, 1e-3, 3e-3))
    f30, g90 = family.build("ffrf"), family.build("gcms")
    data = jsonable({
        "quick": quick, "mesh": list(base.mesh.solid), "ranks": comm.size,
        "machine": f"{platform.machine()} {platform.processor() or ''}, {os.cpu_count()} cores",
        "load_average_start": load0, "speed": spd, "frequencies_hz": f30.modes.frequencies_hz,
        "omega_max": {"ffrf": f30.omega_max(), "gcms": g90.omega_max()}, "steady": steady,
        "ffrf_vs_gcms": cmp_, "means": means, "divergence": div, "window_s": window,
        "steps_ffrf": steps_ffrf, "steps_gcms": steps_gcms,
        "blowup_omega_0.6us": omega_for_blowup(0.6e-6, window), "gram": gram})
    text = render(data)

    if comm.rank == 0:
        with open(os.path.join(out_dir, "reduced.md"), "w") as fh:
            fh.write(text)
        with open(os.path.join(out_dir, "reduced.json"), "w") as fh:
            json.dump(data, fh, indent=1)
    ff, gc = spd
    summary = (f"bench reduced: 1e4 AB2 steps FFRF {ff['solve_s']:.3f} s, GCMS {gc['solve_s']:.3f}"
               f" s; preprocessing FFRF {ff['preprocess_s']:.1f} s, GCMS {gc['preprocess_s']:.1f}"
               f" s; FFRF vs GCMS over 5 ms: {_fmt(cmp_['max_diff_over_peak'][:3], '.1e')} of "
               f"peak; tables in {os.path.join(out_dir, 'reduced.md')}")
    return {"summary": summary, **data}
