"""The Markdown report of ``fxflex compare`` from its JSON-able result (rendered after every
study, so a report exists while the run goes on)."""

from __future__ import annotations

import math

from fxflex.scene import PAPER_DAMPING, Scene

__all__ = ["render", "how", "verdict"]

HOW = {"value": "within 1 point", "bound": "at most the paper's bound",
       "approximate": "within 10 % of the paper's 'approximately'", "verdict": "same verdict",
       "zero": "below 1e-6 % (round-off)", "trend": "the paper's trend", "speedup": "ratio"}


def how(f: dict) -> str:
    """How a row is compared: ``HOW`` of its kind, or "n/a" on a scene that is not the paper's
    (:func:`fxflex.analysis.compare_paper.not_applicable`)."""
    return "n/a" if f.get("applicable") is False else HOW[f["kind"]]


def verdict(f: dict, key: str = "pass") -> str:
    """pass / FAIL / - (undecided), or n/a on a scene that is not the paper's."""
    if f.get("applicable") is False:
        return "n/a"
    return {True: "pass", False: "FAIL", None: "-"}[f[key]]


def _f(x, spec=".5f"):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    if isinstance(x, bool):
        return str(x)
    if isinstance(x, (int, float)):
        return format(x, spec)
    return str(x)


def _mm(v, spec="+.5f"):
    return " / ".join(_f(x, spec) for x in v) if v else "-"


def _table(head, rows) -> list[str]:
    def cell(c):
        return str(c).replace("|", "\\|")
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + \
        ["| " + " | ".join(cell(c) for c in r) + " |" for r in rows]


def _window(s) -> str:
    return f"{s['case']['t_end'] * 1e3:g}"


def _diverged(s) -> str:
    d = s["diverged"]
    return f"{d['time_s'] * 1e3:.3f} ms, {d['cause']}" if d else "no"


def render(scene: Scene, r: dict) -> str:
    w = r["windows"]
    tlf = "the paper window" if w["tlf_s"] is None else ", ".join(
        f"{k} {v * 1e3:g} ms" for k, v in w["tlf_s"].items())
    other = r.get("scene_differences") or []
    lines = ["# fxflex compare: the paper's Sect. 4 on one scene", ""]
    if other:
        lines += ["**Not the paper's scene** (" + ", ".join(f"`{d}`" for d in other) + "): the "
                  "same studies as on the paper's scene, all methods side by side; the paper's "
                  "figures (section 2, 2b) are about its own blade and are marked "
                  "\"n/a (not the paper's scene)\", without a verdict.", ""]
    lines += [
             f"Scene `{scene.hash}`: solid mesh {list(scene.mesh.solid)}, "
             f"{scene.mesh.beam_elements} beam elements, {scene.reduction.ffrf_modes} FFRF modes, "
             f"{scene.reduction.gcms_modes} GCMS global modes (before the Gram cut). Methods: "
             f"{', '.join(m.upper() for m in r['methods'])}. "
             f"{'`--full`' if r['full'] else 'Default run'}: windows {w['paper_s'] * 1e3:g} ms "
             f"(the paper's text gives no time axes), TLF: {tlf}; samples every "
             f"{w['sample_dt_s'] * 1e6:g} us.", "",
             f"{'Finished' if r.get('finished') else 'IN PROGRESS'} after "
             f"{r['seconds']:.0f} s; load average {r['load_average_start']:.2f} at the start, "
             f"{r.get('load_average_end', float('nan')):.2f} now. Time per study (s): "
             + ", ".join(f"{k} {v:.0f}" for k, v in r["timings_s"].items()) + ".", ""]
    lines += (_steady(r) + _paper(r) + _accurate(scene, r) + _speeds(r) + _steps(r)
              + _damping(r) + _efficiency(r))
    lines += ["", "## Files", "",
              "`steady.csv`, `damping_steady.csv` (equilibria), `transients.csv` (one row per "
              "run and study), `paper.csv` (the SPEC section 7 rows), `results.json` "
              "(everything), `series/*.csv` (each run's samples: t, tip deflection, drive torque "
              "where the method gives it, root-section sigma_X max/min), and the figures: "
              + ", ".join(f"[{f}]({f})" for f in r["figures"]) + "."]
    return "\n".join(lines) + "\n"


def _steady(r) -> list[str]:
    rows = [[s["method"], f"{s['rpm']:g}", *(_f(x, "+.5f") for x in s["tip_mm"]),
             _f(s["stable"]), _f(s["growth_rate"], "+.4g"),
             f"{_f(s['sigma_max'] and s['sigma_max'] / 1e6, '+.2f')} / "
             f"{_f(s['sigma_min'] and s['sigma_min'] / 1e6, '+.2f')}",
             _f(s["torque"], "+.2e"), s["dof"], f"{s['seconds']:.1f}"] for s in r["steady"]]
    return ["## 1. Convergent deflections (Tables 1-2), stability, root stress", "",
            "Equilibria in the rotating frame at c3 = 1000 with relative damping (SPEC section 6),"
            " deflections in mm. `stable`: no eigenvalue of the linearised rotating system with "
            "positive real part (`-`: the method offers no eigenvalue analysis); `max Re lambda`: "
            "the largest real part. `sigma_X`: the largest and smallest axial stress at the "
            "corners of the root section (another shape: the vertices of its outer contour), "
            "from the section forces that the elastic force on the "
            "root coordinates carries (beam theory's linear distribution over the section). "
            "`torque`: the drive torque at the equilibrium (relative coordinates at rest; zero "
            "up to round-off with relative damping).", "",
            *_table(["method", "rpm", "longitudinal", "orthogonal", "load", "stable",
                     "max Re lambda 1/s", "sigma_X max / min MPa", "torque N m", "dof", "s"],
                    rows), ""]


def _paper(r) -> list[str]:
    rows = []
    for f in r["paper"]:
        ours = f"{f['ours']:.3g}" if isinstance(f["ours"], float) and abs(f["ours"]) < 1e-3 \
            else (f"{f['ours']:.2f}" if isinstance(f["ours"], float) else str(f["ours"]))
        rows.append([f["figure"], ours, f["paper"], how(f), verdict(f)])
    n_pass = sum(1 for f in r["paper"] if f["pass"])
    if r.get("scene_differences"):
        said = (f"{len(r['paper'])} rows, ours only: the paper's figures are about its own "
                "blade (SPEC section 1), so on this scene they are not applicable and no row "
                "has a verdict. Each row reads the same equilibria and runs as on the paper's "
                "scene, so the methods stand side by side.")
    else:
        said = (f"{n_pass} of {len(r['paper'])} pass. The last rows (Sect. 4.2 and Fig. 5) "
                "are claims about the paper's own code and step choice: we report ours either "
                "way.")
    return ["## 2. SPEC section 7: ours next to the paper's", "", said, "",
            *_table(["figure", "ours", "paper", "how compared", "pass"], rows), ""]


def _accurate(scene: Scene, r: dict) -> list[str]:
    acc = r.get("accurate_solids")
    if not acc:
        return []
    keys = acc["keys"]
    mesh, degree = keys["mesh.solid"], keys["mesh.solid_degree"]
    dof = sorted({s["dof"] for s in acc["steady"]})
    rows, locking = [], []
    for f in acc["paper"]:
        rows.append([f["figure"], f"{f['q1_ours']:.3g}", verdict(f, "q1_pass"),
                     f"{f['ours']:.3g}", verdict(f), f["paper"],
                     "the Q1 mesh's locking" if f["locking"] else ""])
        if f["locking"]:
            locking.append(f["figure"])
    said = (f"{len(locking)} row(s) that fail on the scene's Q1 mesh pass with Q{degree}: they "
            "fail because of the Q1 mesh's locking (its equilibria are 1.6-2.2 % stiff on this "
            "blade, docs/accuracy.md), not because of the formulations." if locking else
            f"No row that fails on the scene's Q1 mesh passes with Q{degree}.")
    if r.get("scene_differences"):
        said = (f"Not the paper's scene: the rows give ours with Q1 and Q{degree} side by side, "
                "without a verdict; their difference is the Q1 mesh's error on this body.")
    return ["## 2b. The rows decided by equilibria, with accurate solids", "",
            f"The solid methods' equilibria again with Q{degree} elements on {mesh} "
            f"({', '.join(map(str, dof))} unknowns, against the scene's Q1 mesh "
            f"{list(scene.mesh.solid)}), the rest unchanged. {said}", "",
            *_table(["figure", "ours (Q1)", "pass", f"ours (Q{degree})", "pass", "paper",
                     "reading"], rows), ""]


def _study(r, name):
    return [t for t in r["transients"] if t["study"] == name]


def _speeds(r) -> list[str]:
    runs = _study(r, "speeds")
    if not runs:
        return []
    figs = [f for f in r["figures"] if f.startswith(("fig4", "fig6", "fig7"))]
    rows = [[t["case"]["method"], f"{t['case']['rpm']:g}",
             f"{t['case']['integrator']} {t['case']['dt'] * 1e6:.4g} us", _window(t),
             _mm(t["final_mm"]), _mm(t["hann_mean_mm"]), _mm(t.get("steady_mm")),
             _mm(t["peak_mm"], ".4f"), _diverged(t),
             f"{_f(t['measured_growth'], '.1f')} / {_f(t['eigen_growth'], '.1f')}",
             f"{_f(t.get('sigma_root_max_MPa'), '+.1f')} / "
             f"{_f(t.get('sigma_root_min_MPa'), '+.1f')}", f"{t['wall_s']:.1f}"] for t in runs]
    out = ["## 3. Transients at paper settings (Fig. 4, 6, 7)", "",
           "Each method with its paper integrator and step, c3, relative damping, from the "
           "undeformed body in rigid rotation with the load ramped over 300 us. The damping is "
           "light (c / rho = 0.13 1/s), so over these windows the deflection oscillates about "
           "the equilibrium rather than settling: `Hann mean` is the Hann-weighted mean over the "
           "window (bounded runs), to be read against the equilibrium of section 1 (its accuracy "
           "depends on how many periods of the lowest mode the window holds). A divergent run "
           "stops when the deflection passes a quarter of the beam length; its cause is "
           "physical (an eigenvalue with positive real part) or numerical (the step), and its "
           "growth, the slope of log |deflection - equilibrium| where that exceeds three times "
           "the equilibrium, is given next to the eigenvalue's real part.", "",
           *[f"![{f}]({f})" for f in figs], "",
           *_table(["method", "rpm", "integrator", "window ms", "end mm", "Hann mean mm",
                    "equilibrium mm", "peak mm", "diverged", "growth measured / eigen 1/s",
                    "sigma_X max / min over the run MPa", "wall s"], rows), ""]
    torque = [t for t in runs if t.get("torque_peak_Nm") is not None]
    if torque:
        eq = {(s["method"], s["rpm"]): s["torque"] for s in r["steady"]}
        out += ["### Drive torque", "",
                "From the methods that give it (the reference-coordinate rows of FFRF, GCMS, "
                "LEBB, NEBB; TLF and ANCF prescribe the root motion and do not compute it). At a "
                "true equilibrium with relative damping the torque vanishes (no dissipation, "
                "radial centrifugal forces, a load along the axis); over the transient it "
                "oscillates with the Coriolis coupling of the vibration, and its Hann mean is "
                "what is left of that average.", "",
                "![drive_torque.png](drive_torque.png)" if "drive_torque.png" in r["figures"]
                else "", "",
                *_table(["method", "rpm", "Hann mean N m", "peak |torque| N m", "at the end N m",
                         "at the equilibrium N m"],
                        [[t["case"]["method"], f"{t['case']['rpm']:g}",
                          _f(t["torque_mean_Nm"], "+.3g"), _f(t["torque_peak_Nm"], ".3g"),
                          _f(t["torque_final_Nm"], "+.3g"),
                          _f(eq.get((t["case"]["method"], t["case"]["rpm"])), "+.2e")]
                         for t in torque]), ""]
    return out


def _steps(r) -> list[str]:
    runs = _study(r, "steps")
    if not runs:
        return []

    def verdict(t):
        if t["diverged"]:
            return f"diverged ({t['diverged']['cause']})"
        v = t.get("vs_half")
        if v is None:
            return "reference"
        return "close" if v < 0.05 else "visibly different"

    rows = [[t["case"]["method"], f"{t['case']['dt'] * 1e6:.4g}" +
             (f" ({t['case']['mass']} mass)" if t["case"]["mass"] else ""), _window(t),
             _f(t.get("vs_half"), ".2e"), _diverged(t), verdict(t),
             (t["diverged"] or {}).get("detail", "")] for t in runs]
    return ["## 4. Time-step study (Fig. 5)", "",
            "1000 rpm, c3: each method at half its paper step, the paper step and 1.2 times it "
            "(the paper's \"slightly larger\"; for FFRF the paper's 0.6 us). `vs half step`: max "
            "|orthogonal difference| over the window / peak of the half-step run. TLF's default "
            "mass is lumped (central-difference limit 2 / w_max = 1.14 us on the default mesh); "
            "the consistent mass of the paper's Eq. 29 has its limit at 0.55 us, between the "
            "paper step and 1.2 times it.", "", "![fig5_steps.png](fig5_steps.png)", "",
            *_table(["method", "dt us", "window ms", "vs half step", "diverged", "verdict",
                     "diagnosis"], rows), ""]


def _damping(r) -> list[str]:
    rows = r["damping_steady"]
    if not rows:
        return []
    out = ["## 5. Damping models (Sect. 4.3, Fig. 8-11)", "",
           "Equilibrium orthogonal deflection (mm) at c1, c2, c3 = " +
           ", ".join(f"{c:g}" for c in PAPER_DAMPING) + " kg s^-1 m^-3. The relative model's "
           "damping force vanishes at the equilibrium (c drops out of it); the absolute model "
           "keeps the circulatory force -c Omega S U, which moves the equilibrium with c.", ""]
    table = {}
    for s in rows:
        table.setdefault((s["method"], s["rpm"], s["model"]), {})[s["c"]] = s["tip_mm"][1]
    body = []
    for (m, rpm, model), vals in table.items():
        v = [vals.get(c) for c in PAPER_DAMPING]
        ok = [x for x in v if x is not None]
        spread = (100 * (max(ok) - min(ok)) / max(abs(x) for x in ok)) if len(ok) > 1 and \
            max(abs(x) for x in ok) > 0 else None
        body.append([m, f"{rpm:g}", model, *(_f(x, "+.7f") for x in v), _f(spread, ".3g")])
    out += _table(["method", "rpm", "model", "c1", "c2", "c3", "spread %"], body)
    if "damping_steady.png" in r["figures"]:
        out += ["", "![damping_steady.png](damping_steady.png)"]
    runs = _study(r, "damping")
    first = {}
    for t in sorted(runs, key=lambda t: t["case"]["c"]):
        first.setdefault((t["case"]["method"], t["case"]["rpm"], t["case"]["model"]), t)

    def shift(t, key):
        a, b = t.get(key), first[(t["case"]["method"], t["case"]["rpm"], t["case"]["model"])].get(key)
        return a[1] - b[1] if a and b else None

    if runs:
        figs = [f for f in r["figures"] if f.startswith(("fig8", "fig9", "fig10", "fig11"))]
        out += ["", "Transients (GCMS at the paper's 0.1 us, TLF and ANCF at their paper steps): "
                "the orthogonal deflection for c1..c3. Over these windows the decay "
                "exp(-c t / (2 rho)) is at most 1e-3, so the curves for different c overlap "
                "(the figures' second row shows their differences from the c1 run): the Hann "
                "means are off the equilibria by what the window leaves of the oscillation, but "
                "their shifts with c are read against the equilibria's shifts (relative model: "
                "zero; absolute model: the circulatory shift).", "",
                *[f"![{f}]({f})" for f in figs], "",
                *_table(["method", "rpm", "model", "c", "window ms", "Hann mean orthogonal mm",
                         "equilibrium orthogonal mm", "mean shift from c1 mm",
                         "equilibrium shift from c1 mm", "diverged"],
                        [[t["case"]["method"], f"{t['case']['rpm']:g}", t["case"]["model"],
                          f"{t['case']['c']:g}", _window(t),
                          _f(t["hann_mean_mm"][1] if t["hann_mean_mm"] else None, "+.6f"),
                          _f(t["steady_mm"][1] if t.get("steady_mm") else None, "+.6f"),
                          _f(shift(t, "hann_mean_mm"), "+.2e"), _f(shift(t, "steady_mm"), "+.2e"),
                          _diverged(t)] for t in runs])]
    return out + [""]


def _efficiency(r) -> list[str]:
    eff = r["efficiency"]
    if not eff:
        return []
    return ["## 6. Efficiency spot check (Sect. 4.2)", "",
            "CPU time per step of the paper's integrator and step with system invariant "
            "matrices and without them (TLF: the UFL residual assembled every step, the "
            "per-step integration of Eq. 65; NEBB: Eq. 66; ANCF: element invariant matrices), "
            "best of three short runs each. `fxflex bench paper` gives the paper's Tables 3-6.",
            "", *_table(["method", "integrator", "invariant ms/step", "without ms/step",
                         "ratio"],
                        [[m, e["integrator"], f"{e['invariant_ms']:.3f}",
                          f"{e['without_ms']:.3f} ({e['without']})", f"{e['ratio']:.2f}"]
                         if "ratio" in e else [m, e["integrator"], "-", f"- ({e['without']})",
                                               f"not measured: {e['skipped']}"]
                         for m, e in eff.items()]), ""]
