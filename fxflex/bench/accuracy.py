"""``fxflex bench accuracy``: run time against error for every method (work-precision, issue 7).

Two errors, two plots, one table each:

(a) **Tip-deflection history.** Each method at the scene's speed over a fixed window (10 ms;
    ``quick``: 1 ms) with central difference, AB2 and generalised-alpha (rho_inf 0.9) at several
    multiples of the paper's step, against a fine-step reference of the same method: central
    difference at a quarter of the paper's step (second order, so it is 16 times closer to the
    truth than the paper's run). Error e = max_t |U(t) - U_ref(t)| / max_t |U_ref(t)| (U the tip
    deflection vector, "1 % of the peak"; :func:`fxflex.bench.implicit.compare`, sampled every
    ~10 us), cost = wall time of the time loop.

(b) **Convergent deflection.** The error |U - U_ref| / |U_ref| of the equilibrium a route
    produces against the converged reference (:mod:`fxflex.analysis.reference`), judged against
    the continuum of the method's own theory (FFRF, GCMS, LEBB: the linear-elastic one; TLF, NEBB,
    ANCF: the nonlinear one) and against the nonlinear truth. Routes:

    - a steady-state solve (SPEC section 6) on the paper's discretisation and on coarser and finer
      ones (solid meshes (16 m, 2 m, m) and TLF with Q2 elements, FFRF mode counts, beam element
      counts); cost = build (caches bypassed) + solve, measured;
    - a transient run until it settles: every mode of the linearised rotating system decays at
      about Re lambda = -c / (2 rho) (``docs/stability.md``), so a transient whose deviation from
      its equilibrium starts at A0 (the largest |U(t) - U_ss| of the fine-step run in the window)
      is within 1 % of it after T = ln(A0 / (0.01 |U_ss|)) / sigma, sigma = -Re lambda of the
      slowest root (``growth_rate()``); cost = build + T / dt steps times the cost per step
      measured in (a). **An estimate**: nobody runs the 70 s. AB2 adds to each root the growth of
      its principal root, ln|z(h lambda)| / h (:func:`fxflex.numerics.growth.ab2_root`); where that
      makes any root grow the run never settles, and the largest step that keeps the slowest
      decay within 90 % of sigma is given instead.

Pareto fronts (no other point both cheaper and more accurate) are named per method in (a), per
method and over all methods (against the nonlinear truth) in (b); the paper's settings are marked.
``reference=True`` (``--reference``) recomputes the converged reference instead (about 25 minutes
on 2 cores) and stores it in ``fxflex/data/reference.json`` (default scene; ``quick``: coarse
levels, not stored). Writes ``accuracy.md``, ``accuracy.json``, ``accuracy_history.png`` and
``accuracy_convergent.png`` (``reference.md``, ``reference.json``, ``reference.png``) to the output
folder; rank 0 writes, every rank computes.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time

import numpy as np

from fxflex import cache
from fxflex.analysis import reference as refmod
from fxflex.bench.common import machine, markdown_table
from fxflex.bench.implicit import compare
from fxflex.bench.implicit import reference as fine_reference
from fxflex.formulation import METHODS, PAPER_INTEGRATION, build
from fxflex.io.payload import jsonable
from fxflex.methods import formulation_class
from fxflex.scene import PAPER_RPM, Scene

__all__ = ["run", "pareto", "settling", "OWN_THEORY"]

#: the continuum each method approximates (its own theory)
OWN_THEORY = {"ffrf": "linear", "gcms": "linear", "lebb": "linear", "tlf": "tlf", "nebb": "tlf",
              "ancf": "tlf"}
WINDOW, QUICK_WINDOW = 0.01, 0.001
#: steps as multiples of the paper's step, per integrator
FACTORS = {"cd": (1, 2, 4), "ab2": (0.5, 1, 2), "generalized-alpha": (10, 20, 40, 80, 160)}
QUICK_FACTORS = {"cd": (1,), "ab2": (1,), "generalized-alpha": (10, 40)}
RHO_INF = 0.9
REF_FRACTION = 0.25            # fine-step reference: central difference at 1/4 of the paper step
SAMPLE_DT = 10e-6
SETTLE = 0.01                  # "settled": within 1 % of the equilibrium
COARSE = (10, 2, 2)            # quick: the solid methods' mesh
#: discretisations of the steady-state routes (solid mesh levels m of (16 m, 2 m, m))
ROUTES = {"tlf": {"Q1": (2, 4, 8, 12), "Q2": (1, 2, 3, 4)}, "reduced": (2, 4, 8, 12),
          "modes": (10, 60), "beam": (2, 5, 20, 40)}
QUICK_ROUTES = {"tlf": {"Q1": (2,), "Q2": (1,)}, "reduced": (), "modes": (), "beam": (5,)}
#: the modal truncation is studied on FFRF (GCMS's count is what its Gram cut keeps)
MODAL_STUDY = {"ffrf": "reduction.ffrf_modes"}


def _log(comm, text: str) -> None:
    if comm.rank == 0:
        sys.stderr.write(text + "\n")
        sys.stderr.flush()


def pareto(points) -> list[int]:
    """Indices of the points (cost, error) that no other point beats in both (ties kept),
    cheapest first."""
    pts = [(c, e, i) for i, (c, e) in enumerate(points) if np.isfinite(c) and np.isfinite(e)]
    pts.sort()
    front, best = [], math.inf
    for c, e, i in pts:
        if e < best:
            front.append(i)
            best = e
    return front


def settling(amplitude: float, steady: float, decay: float, fraction: float = SETTLE) -> float:
    """Time (s) for a deviation starting at ``amplitude`` and decaying at ``decay`` (1/s) to fall
    below ``fraction`` of ``steady``: ln(A0 / (fraction |U_ss|)) / sigma (0 if already there)."""
    if decay <= 0.0:
        return math.inf
    return max(0.0, math.log(amplitude / (fraction * steady)) / decay)


def _ab2_rate(form, dt: float, sigma: float) -> float | None:
    """Largest ln|z| / dt of AB2's principal root over the roots lambda of the linearised rotating
    system: Re lambda plus AB2's numerical growth. Dense models (``all_roots``): every root; TLF:
    its highest frequency w_max with Re lambda = -sigma (the law of NOTES.md is this root's
    small-h limit)."""
    from fxflex.numerics.growth import ab2_root

    if form.all_roots:
        lam = np.asarray(form.eigenvalues())
    else:                           # the lowest roots only: the highest frequency stands in
        lam = np.array([complex(-sigma, form.omega_max())])
    return float(np.max(np.log(ab2_root(dt * lam)) / dt))


def _ab2_settling_step(form, dt0: float, sigma: float) -> float | None:
    """Largest step below dt0 (bisection in log dt) at which no root grows under AB2."""
    lo, hi = dt0 * 1e-4, dt0
    if _ab2_rate(form, lo, sigma) >= 0.0:
        return None
    for _ in range(40):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if _ab2_rate(form, mid, sigma) < 0.0 else (lo, mid)
    return lo


# -- (b) steady-state routes ---------------------------------------------------------------------
def _timed_build_steady(method: str, scene: Scene, comm) -> tuple[object, object, float, float]:
    """Build from nothing (caches bypassed) and solve the steady state: (form, steady, build s,
    solve s)."""
    t0 = time.perf_counter()
    with cache.bypass():
        form = build(method, scene, comm)
    t1 = time.perf_counter()
    st = form.steady_state()
    return form, st, t1 - t0, time.perf_counter() - t1


def _errors(tip, ref: dict, rpm: float) -> dict:
    out = {}
    for theory in refmod.THEORIES:
        entry = ref["theories"].get(theory, {}).get(f"{rpm:g}")
        out[theory] = None if entry is None else refmod.relative_error(tip, entry["reference_m"])
    return out


def _route(method: str, label: str, dof: int, build_s: float, solve_s: float, tip, ref: dict,
           rpm: float, paper: bool = False) -> dict:
    err = _errors(tip, ref, rpm)
    return {"method": method, "route": label, "kind": "steady", "dof": dof, "build_s": build_s,
            "solve_s": solve_s, "cost_s": build_s + solve_s, "tip_m": list(map(float, tip)),
            "error_own": err[OWN_THEORY[method]], "error_truth": err["tlf"], "paper": paper}


def steady_routes(scene: Scene, comm, ref: dict, quick: bool, log) -> list[dict]:
    """Every method's steady state on several discretisations at the scene's speed."""
    from fxflex.solid.model import SolidModel
    from fxflex.solid.tlf import tlf_steady

    routes = QUICK_ROUTES if quick else ROUTES
    rpm = scene.rotation.rpm
    rows = []
    for method in METHODS:
        traits = formulation_class(method)
        if traits.mesh_key == "mesh.solid":     # the distributed TLF on its own (cheaper) levels
            levels = routes["tlf"]["Q1"] if traits.distributed else routes["reduced"]
            variants = [(f"steady Q1 {list(refmod.divisions(m))}",
                         scene.replace(**{"mesh.solid": refmod.divisions(m)})) for m in levels]
        else:
            variants = [(f"steady, {n} elements", scene.replace(**{traits.mesh_key: n}))
                        for n in routes["beam"]]
        if method in MODAL_STUDY:
            variants += [(f"steady, {n} modes", scene.replace(**{MODAL_STUDY[method]: n}))
                         for n in routes["modes"]]
        for label, sc in variants:
            form, st, b, s = _timed_build_steady(method, sc, comm)
            rows.append(_route(method, label, form.dof, b, s, st.tip, ref, rpm))
            log(f"  {method} {label}: error {100 * rows[-1]['error_own']:.3f} % (own theory), "
                f"{b + s:.2f} s")
        if traits.distributed:                  # TLF at higher order: the reference module's Q2
            for m in routes["tlf"]["Q2"]:
                t0 = time.perf_counter()
                with cache.bypass():
                    model = SolidModel(scene, comm, divisions=refmod.divisions(m), degree=2)
                t1 = time.perf_counter()
                st = tlf_steady(model)
                t2 = time.perf_counter()
                rows.append(_route(method, f"steady Q2 {list(refmod.divisions(m))}", model.dof,
                                   t1 - t0, t2 - t1, st.tip, ref, rpm))
                log(f"  tlf Q2 m={m}: error {100 * rows[-1]['error_own']:.3f} %, "
                    f"{t2 - t0:.2f} s")
    return rows


# -- (a) histories, and the settling estimate ----------------------------------------------------
def transients(form, steady_tip, window: float, factors: dict, log) -> dict:
    """Fine-step reference, every (integrator, step) of ``factors`` against it, and the settling
    estimate of the method at the scene's speed."""
    method = form.method
    paper_integrator, paper_dt = PAPER_INTEGRATION[method]
    t0 = time.perf_counter()
    ref = fine_reference(form, window, "cd", REF_FRACTION * paper_dt)
    log(f"  {method}: reference cd {1e6 * ref.dt:.3g} us, {ref.steps} steps, "
        f"{time.perf_counter() - t0:.1f} s")
    rows = []
    for integrator, facs in factors.items():
        for f in facs:
            dt = f * paper_dt
            r = compare(form, ref, dt, RHO_INF if integrator == "generalized-alpha" else None,
                        window, integrator=integrator, sample_dt=SAMPLE_DT)
            r["factor"] = f
            r["paper"] = integrator == paper_integrator and f == 1
            rows.append(r)
            state = (f"diverged at {1e3 * r['diverged']['time_s']:.3g} ms" if r["diverged"]
                     else f"error {100 * r['error']:.3g} %")
            log(f"  {method} {integrator} {1e6 * dt:.3g} us: {state}, "
                f"{r['us_per_step']:.1f} us/step")
    # settling: slowest decay of the linearised system and the initial deviation A0
    rate, _ = form.growth_rate()
    sigma = -rate
    steady_norm = float(np.linalg.norm(steady_tip))
    amplitude = float(np.linalg.norm(ref.tip - np.asarray(steady_tip), axis=1).max())
    settle = {"sigma": sigma, "A0_m": amplitude, "steady_norm_m": steady_norm,
              "T_s": settling(amplitude, steady_norm, sigma) if sigma > 0 else math.inf}
    for r in rows:
        # every run is judged by the physical decay; AB2 runs whose fastest root grows never
        # settle (the highest modes start tiny, but grow without bound over T)
        g = _ab2_rate(form, r["dt_s"], sigma) if r["integrator"] == "ab2" and sigma > 0 else None
        r["ab2_rate"] = g
        r["settles"] = bool(not r["diverged"] and sigma > 0 and (g is None or g < 0.0))
        r["settle_s"] = settle["T_s"]
        r["settle_steps"] = settle["T_s"] / r["dt_s"]
        r["settle_cost_s"] = r["settle_steps"] * 1e-6 * r["us_per_step"]
    if paper_integrator == "ab2" and sigma > 0:
        settle["ab2_settling_dt_s"] = _ab2_settling_step(form, paper_dt, sigma)
    return {"method": method, "dof": form.dof,
            "reference": {"integrator": "cd", "dt_s": ref.dt, "steps": ref.steps,
                          "wall_s": ref.wall_s, "peak_m": ref.peak},
            "rows": rows, "settle": settle}


# -- the study -----------------------------------------------------------------------------------
def discretisation_table(scene: Scene, comm, ref: dict, speeds, log) -> list[dict]:
    """Every method's steady state on its paper discretisation (the scene's mesh, modes,
    elements) at each speed, against both references."""
    rows = []
    for method in METHODS:
        for rpm in speeds:
            sc = scene.replace(**{"rotation.rpm": float(rpm)})
            form, st, b, s = _timed_build_steady(method, sc, comm)
            rate, _ = form.growth_rate()
            row = _route(method, "paper discretisation", form.dof, b, s, st.tip, ref, rpm,
                         paper=True)
            err = _errors(st.tip, ref, rpm)
            row.update(rpm=float(rpm), error_linear=err["linear"], error_tlf=err["tlf"],
                       stable=rate <= 0.0, growth_rate=rate, converged=st.converged)
            row["component_errors"] = {
                th: (None if ref["theories"].get(th, {}).get(f"{rpm:g}") is None else
                     (np.abs(np.asarray(st.tip) - ref["theories"][th][f"{rpm:g}"]["reference_m"])
                      / np.abs(ref["theories"][th][f"{rpm:g}"]["reference_m"])).tolist())
                for th in refmod.THEORIES}
            rows.append(row)
            log(f"  {method} {rpm:g} rpm: error {100 * err['linear']:.3f} % vs linear, "
                f"{100 * err['tlf']:.3f} % vs TLF continuum")
    return rows


def _get_reference(scene: Scene, comm, quick: bool, log) -> dict:
    ref = refmod.stored_reference(scene)
    if ref is not None:
        log(f"converged reference: stored ({refmod.STORE})")
        return ref
    log("converged reference: none stored for this scene; computing the coarse (quick) levels")
    speeds = (scene.rotation.rpm,) if quick else PAPER_RPM
    ref = refmod.converged_reference(scene, comm, speeds=speeds, quick=True,
                                     log=lambda s: _log(comm, s))
    ref["note"] = "computed on the fly with the quick levels (no stored reference for the scene)"
    return ref


def run(scene: Scene, out_dir: str, comm, quick: bool = False, reference: bool = False) -> dict:
    def log(text):
        _log(comm, text)

    info = {"machine": machine(), "load_start": os.getloadavg()[0], "ranks": comm.size}
    if reference:
        return _run_reference(scene, out_dir, comm, quick, info, log)
    ref = _get_reference(scene, comm, quick, log)
    if quick:
        scene = scene.replace(**{"mesh.solid": COARSE})
    speeds = (scene.rotation.rpm,) if quick else PAPER_RPM
    log("discretisation errors of the paper's discretisations:")
    table = discretisation_table(scene, comm, ref, speeds, log)
    log("steady-state routes:")
    routes = steady_routes(scene, comm, ref, quick, log)
    log("transients:")
    window = QUICK_WINDOW if quick else WINDOW
    studies = []
    for method in METHODS:
        form = build(method, scene, comm)
        st = form.steady_state()
        studies.append(transients(form, st.tip, window, QUICK_FACTORS if quick else FACTORS,
                                  log))
    info["load_end"] = os.getloadavg()[0]
    result = assemble(scene, ref, table, routes, studies, window, info)
    if comm.rank == 0:
        with open(os.path.join(out_dir, "accuracy.md"), "w") as fh:
            fh.write(result["report"])
        with open(os.path.join(out_dir, "accuracy.json"), "w") as fh:
            json.dump(jsonable({k: v for k, v in result.items() if k != "report"}), fh,
                      indent=1)
        _plot_history(studies, os.path.join(out_dir, "accuracy_history.png"), window)
        _plot_convergent(result, os.path.join(out_dir, "accuracy_convergent.png"))
    return {"summary": result["summary"] + f"\n(tables in {out_dir}/accuracy.md)",
            "info": info, "fastest": result["fastest"], "tlf_transient": result["tlf_transient"]}


# -- assembling the tables -----------------------------------------------------------------------
def _route_label(r: dict) -> str:
    return (f"{r['integrator']} {1e6 * r['dt_s']:.3g} us" if r.get("kind") == "transient"
            else r["route"])


def assemble(scene: Scene, ref: dict, table: list[dict], routes: list[dict],
             studies: list[dict], window: float, info: dict) -> dict:
    """Pareto fronts, the fastest route to 1 % per method, the TLF transient speed-up, the
    Markdown report and the one-paragraph summary."""
    rpm = scene.rotation.rpm
    paper_rows = {r["method"]: r for r in table if r["rpm"] == rpm}
    # (b): every route of a method: steady ones, and its transients (settled within 1 %)
    b_routes: dict[str, list[dict]] = {}
    for method in METHODS:
        pr = paper_rows[method]
        lst = [pr] + [r for r in routes if r["method"] == method]
        st = next(s for s in studies if s["method"] == method)
        for r in st["rows"]:
            if not r["settles"] or not math.isfinite(r["settle_cost_s"]):
                continue
            lst.append({"method": method, "kind": "transient", "integrator": r["integrator"],
                        "dt_s": r["dt_s"], "route": f"{r['integrator']} {1e6 * r['dt_s']:.3g} us",
                        "cost_s": pr["build_s"] + r["settle_cost_s"],
                        "error_own": pr["error_own"], "error_truth": pr["error_truth"],
                        "settle_s": r["settle_s"], "paper": r["paper"]})
        b_routes[method] = lst
    fastest = {}
    for method, lst in b_routes.items():
        st = next(s for s in studies if s["method"] == method)
        settle = st["settle"]
        paper_t = next((r for r in st["rows"] if r["paper"]), None)
        build_s = paper_rows[method]["build_s"]
        # the issue's estimate: the paper's step, whether or not AB2 settles there ...
        nominal = (build_s + paper_t["settle_cost_s"]) if paper_t is not None else math.inf
        # ... and the step at which it does
        h = settle.get("ab2_settling_dt_s")
        settling_cost = (nominal if paper_t is not None and paper_t["settles"] else
                         build_s + settle["T_s"] / h * 1e-6 * paper_t["us_per_step"]
                         if paper_t is not None and h else math.inf)
        ok = [r for r in lst if r["error_own"] is not None and r["error_own"] <= 0.01]
        best = min(ok, key=lambda r: r["cost_s"]) if ok else None
        most = min(lst, key=lambda r: (r["error_own"], r["cost_s"]))
        fastest[method] = {
            "paper_route": {"integrator": PAPER_INTEGRATION[method][0],
                            "dt_s": PAPER_INTEGRATION[method][1],
                            "settle_s": settle["T_s"],
                            "steps": paper_t["settle_steps"] if paper_t else None,
                            "us_per_step": paper_t["us_per_step"] if paper_t else None,
                            "ab2_rate": paper_t.get("ab2_rate") if paper_t else None,
                            "settles": paper_t["settles"] if paper_t else False,
                            "cost_s": nominal, "settling_dt_s": h,
                            "settling_cost_s": settling_cost,
                            "error_own": paper_rows[method]["error_own"],
                            "error_truth": paper_rows[method]["error_truth"]},
            "best": None if best is None else {k: best.get(k) for k in
                                               ("route", "kind", "cost_s", "error_own",
                                                "error_truth", "dof")},
            "speedup": (nominal / best["cost_s"]) if best is not None else None,
            "speedup_settling": (settling_cost / best["cost_s"]) if best is not None else None,
            "most_accurate": {k: most.get(k) for k in ("route", "cost_s", "error_own")},
            "pareto": [_route_label(lst[i]) for i in
                       pareto([(r["cost_s"], r["error_own"]) for r in lst])],
        }
    everything = [r for lst in b_routes.values() for r in lst]
    front_all = [f"{everything[i]['method']} {_route_label(everything[i])}" for i in
                 pareto([(r["cost_s"], r["error_truth"]) for r in everything])]
    # (a): Pareto per method, and the TLF 10 ms transient at 1 % of the peak
    for st in studies:
        rows = st["rows"]
        st["pareto"] = [f"{rows[i]['integrator']} {1e6 * rows[i]['dt_s']:.3g} us" for i in
                        pareto([(r.get("wall_s", math.inf), r["error"]) for r in rows])]
    tlf = next(s for s in studies if s["method"] == "tlf")
    cd = next((r for r in tlf["rows"] if r["paper"]), None)
    ga_ok = [r for r in tlf["rows"] if r["integrator"] == "generalized-alpha"
             and r["error"] <= 0.01]
    best_ga = min(ga_ok, key=lambda r: r["wall_s"]) if ga_ok else None
    tlf_transient = {"cd_wall_s": cd["wall_s"] if cd else None,
                     "cd_error": cd["error"] if cd else None,
                     "best": None if best_ga is None else
                     {"dt_s": best_ga["dt_s"], "wall_s": best_ga["wall_s"],
                      "error": best_ga["error"]},
                     "speedup": (cd["wall_s"] / best_ga["wall_s"]) if cd and best_ga else None}
    result = {"scene_rpm": rpm, "window_s": window, "info": info,
              "reference": {"key": ref["key"], "quick": ref.get("quick"),
                            "note": ref.get("note"),
                            "theories": {th: {k: {kk: v[kk] for kk in
                                                  ("reference_m", "error_estimate_m",
                                                   "relative_error_estimate")}
                                              for k, v in ent.items()}
                                         for th, ent in ref["theories"].items()}},
              "discretisation": table, "routes": b_routes, "studies": studies,
              "fastest": fastest, "pareto_all_truth": front_all, "tlf_transient": tlf_transient}
    result["report"] = _report(result, scene)
    result["summary"] = _summary(result)
    return result


def _pct(x, digits=3) -> str:
    if x is None:
        return "-"
    if not math.isfinite(x):
        return "inf"
    return f"{100 * x:.{digits}g}"


def _times(x) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.3g}x"


def _secs(x) -> str:
    if x is None or not math.isfinite(x):
        return "-"
    if x >= 86400:
        return f"{x:.3g} ({x / 86400:.3g} d)"
    if x >= 3600:
        return f"{x:.3g} ({x / 3600:.3g} h)"
    return f"{x:.3g}"


def _report(res: dict, scene: Scene) -> str:
    info = res["info"]
    m = info["machine"]
    rpm = res["scene_rpm"]
    ref = res["reference"]
    out = ["# Work-precision: run time against error", "",
           f"{m['cpu']}, {m['cores']} cores, {m['date']}, {info['ranks']} rank(s); load average "
           f"{info['load_start']:.2f} at the start, {info.get('load_end', float('nan')):.2f} at "
           f"the end. Scene speed {rpm:g} rpm, damping c = {scene.damping.c:g} "
           f"({scene.damping.model}).", ""]
    if ref.get("note"):
        out += [f"**Reference: {ref['note']}.**", ""]
    out += ["## Converged reference (mm; error estimate)", ""]
    head = ["theory", "rpm", "longitudinal", "orthogonal", "load", "relative error estimate"]
    rows = []
    for th, ent in ref["theories"].items():
        for sp, e in ent.items():
            rows.append([th, sp] + [f"{1e3 * v:.6f} +- {1e3 * d:.1g}" for v, d in
                                    zip(e["reference_m"], e["error_estimate_m"])]
                        + [f"{e['relative_error_estimate']:.1e}"])
    out.append(markdown_table(head, rows))
    out += ["## Discretisation error of each method on its paper discretisation", "",
            "|U - U_ref| / |U_ref| against the linear-elastic and the nonlinear (TLF) continuum; "
            "**bold** = the method's own theory.", ""]
    head = ["method", "rpm", "dof", "vs linear %", "vs TLF %", "per component vs own % (long./"
            "orth./load)", "stable", "build + solve s"]
    rows = []
    for r in res["discretisation"]:
        own = OWN_THEORY[r["method"]]
        lin, nl = _pct(r["error_linear"]), _pct(r["error_tlf"])
        lin, nl = (f"**{lin}**", nl) if own == "linear" else (lin, f"**{nl}**")
        comp = r["component_errors"][own]
        rows.append([r["method"], f"{r['rpm']:g}", r["dof"], lin, nl,
                     " / ".join(_pct(c) for c in comp) if comp else "-",
                     "yes" if r["stable"] else "**no**", f"{r['cost_s']:.3g}"])
    out.append(markdown_table(head, rows))
    out += [f"## (a) Tip-deflection history over {1e3 * res['window_s']:g} ms against a fine "
            f"step (CD at 1/4 of the paper's step)", "",
            "error = max_t |U - U_ref| / max_t |U_ref|; cost = wall time of the loop; * = the "
            "paper's setting.", ""]
    head = ["method", "integrator", "dt us", "x paper", "error %", "wall s", "us/step"]
    rows = []
    for st in res["studies"]:
        for r in st["rows"]:
            err = (f"diverged at {1e3 * r['diverged']['time_s']:.3g} ms" if r["diverged"]
                   else _pct(r["error"]))
            rows.append([st["method"], r["integrator"] + (" *" if r["paper"] else ""),
                         f"{1e6 * r['dt_s']:.3g}", f"{r['factor']:g}", err,
                         f"{r.get('wall_s', float('nan')):.3g}", f"{r['us_per_step']:.3g}"])
    out.append(markdown_table(head, rows))
    out.append("Pareto fronts (cheapest first):\n")
    out += [f"- {st['method']}: " + ", ".join(st["pareto"]) for st in res["studies"]]
    t = res["tlf_transient"]
    if t["best"] is not None and t["cd_wall_s"]:
        out += ["", f"**TLF, {1e3 * res['window_s']:g} ms transient at 1 % of the peak:** CD at "
                f"the paper's 0.5 us takes {t['cd_wall_s']:.3g} s (error "
                f"{_pct(t['cd_error'])} %), generalised-alpha at {1e6 * t['best']['dt_s']:.3g} us "
                f"{t['best']['wall_s']:.3g} s (error {_pct(t['best']['error'])} %): "
                f"**{t['speedup']:.3g}x** (target 3x)."]
    out += ["", "## (b) Convergent deflection: fastest route to 1 % error", "",
            "Error against the continuum of the method's own theory. The paper's route: its "
            "integrator at its step until the transient settles within 1 % of its equilibrium, "
            "T = ln(A0 / (0.01 |U_ss|)) / sigma (an estimate: sigma the slowest decay rate of the "
            "linearised rotating system, A0 the largest deviation from the equilibrium in the "
            "fine-step window), cost = build + T / dt x the measured cost per step.", ""]
    head = ["method", "sigma 1/s", "A0 / U_ss", "T s", "paper route", "steps", "us/step",
            "est. cost s", "its error %", "fastest route <= 1 %", "error %", "cost s",
            "speed-up"]
    rows = []
    for st in res["studies"]:
        method = st["method"]
        f = res["fastest"][method]
        p = f["paper_route"]
        s = st["settle"]
        route = f"{p['integrator']} {1e6 * p['dt_s']:.3g} us"
        cost = _secs(p["cost_s"])
        speed = _times(f["speedup"])
        if not p["settles"] and p["ab2_rate"] is not None:
            route += f" (AB2: fastest root grows at {p['ab2_rate']:.3g} 1/s, never settles)"
            if p["settling_dt_s"]:
                cost += (f"; at {1e6 * p['settling_dt_s']:.3g} us, where no root grows: "
                         f"{_secs(p['settling_cost_s'])}")
                speed += f"; {_times(f['speedup_settling'])}"
        b = f["best"]
        rows.append([method, f"{s['sigma']:.4g}", f"{s['A0_m'] / s['steady_norm_m']:.3g}",
                     _secs(s["T_s"]), route,
                     f"{p['steps']:.3g}" if p["steps"] is not None else "-",
                     f"{p['us_per_step']:.3g}" if p["us_per_step"] else "-",
                     cost, _pct(p["error_own"]),
                     b["route"] if b else f"none (best: {f['most_accurate']['route']}, "
                                          f"{_pct(f['most_accurate']['error_own'])} %)",
                     _pct(b["error_own"]) if b else "-", f"{b['cost_s']:.3g}" if b else "-",
                     speed])
    out.append(markdown_table(head, rows))
    out.append("Every route (steady: measured; transient: estimated cost to settle within 1 %, "
               "error of the equilibrium it settles to):\n")
    head = ["method", "route", "dof", "cost s", "error vs own %", "error vs TLF %"]
    rows = []
    for method, lst in res["routes"].items():
        for r in sorted(lst, key=lambda r: r["cost_s"]):
            rows.append([method, _route_label(r) + (" *" if r.get("paper") else ""),
                         r.get("dof", "-"), _secs(r["cost_s"]), _pct(r["error_own"]),
                         _pct(r["error_truth"])])
    out.append(markdown_table(head, rows))
    out.append("Pareto fronts (cost, error vs own theory), cheapest first:\n")
    out += [f"- {m}: " + ", ".join(f["pareto"]) for m, f in res["fastest"].items()]
    out += ["", "Over all methods against the nonlinear truth: " + ", ".join(
        res["pareto_all_truth"]), ""]
    return "\n".join(out) + "\n"


def _summary(res: dict) -> str:
    lines = []
    for method, f in res["fastest"].items():
        b = f["best"]
        lines.append(f"{method}: " + (f"fastest to 1 %: {b['route']} ({_pct(b['error_own'])} %, "
                                      f"{b['cost_s']:.3g} s), {_times(f['speedup'])} over the "
                                      f"paper's route (est. {_secs(f['paper_route']['cost_s'])} s)"
                                      if b else
                                      f"no route within 1 % (best "
                                      f"{_pct(f['most_accurate']['error_own'])} %)"))
    t = res["tlf_transient"]
    if t["speedup"]:
        lines.append(f"TLF {1e3 * res['window_s']:g} ms transient at 1 % of the peak: "
                     f"generalised-alpha {1e6 * t['best']['dt_s']:.3g} us is {t['speedup']:.3g}x "
                     f"faster than CD at the paper's step")
    return "\n".join(lines)


# -- plots ---------------------------------------------------------------------------------------
def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


MARKERS = {"cd": "s", "ab2": "^", "generalized-alpha": "o", "steady": "D"}


def _plot_history(studies: list[dict], path: str, window: float) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 5.5))
    for k, st in enumerate(studies):
        color = f"C{k}"
        for integ in ("cd", "ab2", "generalized-alpha"):
            rows = sorted((r for r in st["rows"] if r["integrator"] == integ and not r["diverged"]
                           and r["error"] > 0), key=lambda r: r["wall_s"])
            if rows:
                ax.loglog([r["wall_s"] for r in rows], [100 * r["error"] for r in rows],
                          MARKERS[integ] + "-", color=color, ms=5, lw=0.8,
                          label=f"{st['method']} {integ}")
        for r in st["rows"]:
            if r["paper"] and not r["diverged"] and r["error"] > 0:
                ax.plot(r["wall_s"], 100 * r["error"], "*", color=color, ms=16, mfc="none")
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.set_xlabel("wall time of the time loop (s)")
    ax.set_ylabel("max |U - U_ref| / max |U_ref| (%)")
    ax.set_title(f"{1e3 * window:g} ms transient against CD at 1/4 of the paper step "
                 "(star: paper's setting)", fontsize=9)
    ax.grid(True, which="both", lw=0.3)
    ax.legend(fontsize=6, ncol=3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_convergent(res: dict, path: str) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 5.5))
    for k, (method, lst) in enumerate(res["routes"].items()):
        color = f"C{k}"
        st = [r for r in lst if r["kind"] == "steady" and r["error_own"]]
        st.sort(key=lambda r: r["cost_s"])
        ax.loglog([r["cost_s"] for r in st], [100 * r["error_own"] for r in st], "D",
                  color=color, ms=5, label=f"{method} steady")
        tr = [r for r in lst if r["kind"] == "transient" and r["error_own"]]
        if tr:
            ax.loglog([r["cost_s"] for r in tr], [100 * r["error_own"] for r in tr], "o",
                      color=color, mfc="none", ms=5, label=f"{method} transient (est.)")
        for r in lst:
            if r.get("paper") and r["kind"] == "transient":
                ax.plot(r["cost_s"], 100 * r["error_own"], "*", color=color, ms=16, mfc="none")
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.set_xlabel("cost (s): build + solve, or build + settling estimate")
    ax.set_ylabel("|U - U_ref| / |U_ref| against the own theory's continuum (%)")
    ax.set_title("convergent deflection (star: paper's explicit route, settled within 1 %)",
                 fontsize=9)
    ax.grid(True, which="both", lw=0.3)
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# -- --reference ---------------------------------------------------------------------------------
def _run_reference(scene: Scene, out_dir: str, comm, quick: bool, info: dict, log) -> dict:
    log("converged reference: " + ("quick levels" if quick else "Q2 m = 3, 4, 6, 8 and Q1 m = 4, "
                                   "6, 8, 12 at 1000, 5000, 10000 rpm (about 25 minutes)"))
    ref = refmod.converged_reference(scene, comm, quick=quick, log=log)
    ref["command"] = "fxflex bench accuracy --reference" + (" --quick" if quick else "")
    ref["scene"] = scene.to_dict()

    def save():
        if comm.rank == 0:
            refmod.save_reference(ref, os.path.join(out_dir, "reference.json"))
            if not quick:
                refmod.save_reference(ref, refmod.STORE)

    save()                                  # the expensive part is kept whatever follows
    log("discretisation errors of the paper's discretisations:")
    table = discretisation_table(scene, comm, ref, PAPER_RPM, log)
    ref["discretisation"] = jsonable(table)
    info["load_end"] = os.getloadavg()[0]
    report = _reference_report(ref, table, info)
    save()
    if comm.rank == 0:
        with open(os.path.join(out_dir, "reference.md"), "w") as fh:
            fh.write(report)
        _plot_reference(ref, os.path.join(out_dir, "reference.png"))
    lines = [f"{th} {sp} rpm: " + " / ".join(f"{1e3 * v:.6f}" for v in e["reference_m"])
             + f" mm (+- {e['relative_error_estimate']:.1e})"
             for th, ent in ref["theories"].items() for sp, e in ent.items()]
    return {"summary": "\n".join(lines) + f"\n(tables in {out_dir}/reference.md"
            + ("" if quick else f"; stored in {refmod.STORE}") + ")", "info": info,
            "reference": ref["theories"]}


def _reference_report(ref: dict, table: list[dict], info: dict) -> str:
    m = info["machine"]
    out = ["# Converged reference for the convergent deflections", "",
           f"`{ref['command']}`: {m['cpu']}, {m['cores']} cores, {m['date']}; load average "
           f"{ref['load_start']:.2f} -> {ref['load_end']:.2f}; {ref['wall_s']:.0f} s.", ""]
    head = ["theory", "rpm", "family", "m", "divisions", "dof", "longitudinal mm",
            "orthogonal mm", "load mm", "Newton it", "solve s"]
    rows = [[r["theory"], f"{r['rpm']:g}", r["family"], r["m"], "x".join(map(str, r["divisions"])),
             r["dof"], *(f"{1e3 * v:.6f}" for v in r["tip_m"]), r["iterations"],
             f"{r['solve_s']:.3g}"] for r in ref["levels"]]
    out.append(markdown_table(head, rows))
    head = ["theory", "rpm", "component", "Q2 order", "Q2 extrapolated mm", "previous triple mm",
            "Q1 order", "Q1 extrapolated mm", "reference mm", "error estimate mm"]
    rows = []
    for th, ent in ref["theories"].items():
        for sp, e in ent.items():
            for k, comp in enumerate(refmod.COMPONENTS):
                def mm(x):
                    return "-" if x is None else f"{1e3 * x:.6f}"

                def order(x):
                    return "-" if x is None else f"{x:.2f}"
                rows.append([th, sp, comp, order(e["Q2"]["order"][k]),
                             mm(e["Q2"]["extrapolated_m"][k]), mm(e["Q2"]["previous_m"][k]),
                             order(e["Q1"]["order"][k]), mm(e["Q1"]["extrapolated_m"][k]),
                             mm(e["reference_m"][k]), f"{1e3 * e['error_estimate_m'][k]:.1e}"])
    out.append(markdown_table(head, rows))
    head = ["method", "rpm", "vs linear %", "vs TLF %", "stable"]
    out.append("Paper discretisations against the reference:\n")
    out.append(markdown_table(head, [[r["method"], f"{r['rpm']:g}", _pct(r["error_linear"]),
                                      _pct(r["error_tlf"]), r["stable"]] for r in table]))
    return "\n".join(out) + "\n"


def _plot_reference(ref: dict, path: str) -> None:
    """|f - f_ref| / |U_ref| of each level against the unknowns, both families and theories."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), sharey=True)
    for ax, th in zip(axes, refmod.THEORIES):
        for k, sp in enumerate(ref["theories"].get(th, {})):
            e = ref["theories"][th][sp]
            norm = np.linalg.norm(e["reference_m"])
            for fam, style in (("Q2", "o-"), ("Q1", "s--")):
                lv = sorted((r for r in ref["levels"] if r["theory"] == th
                             and f"{r['rpm']:g}" == sp and r["family"] == fam),
                            key=lambda r: r["dof"])
                err = [np.linalg.norm(np.subtract(r["tip_m"], e["reference_m"])) / norm
                       for r in lv]
                ax.loglog([r["dof"] for r in lv], err, style, color=f"C{k}", ms=4,
                          label=f"{fam} {sp} rpm")
        ax.set_title(f"{th} equilibrium", fontsize=9)
        ax.set_xlabel("unknowns")
        ax.grid(True, which="both", lw=0.3)
        ax.legend(fontsize=7)
    axes[0].set_ylabel("|U - U_ref| / |U_ref|")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
