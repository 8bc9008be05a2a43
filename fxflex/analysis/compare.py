"""``fxflex compare``: the paper's Sect. 4 on one scene (Tables 1-2, Fig. 4-11, SPEC section 7).

Studies, in the order they run (each writes its files into the output folder as it finishes):

1. **Steady states** of every method at 1000, 5000 and 10000 rpm (c3, relative damping): the
   convergent deflections of Tables 1-2, the stability verdict (no eigenvalue of the linearised
   rotating system with positive real part, where the method offers it), the largest and
   smallest axial stress at the root section (``root_stress``: section forces spread over the
   corners) and the drive torque at the equilibrium. Per-step costs are probed here and the
   run-time estimate printed.
1b. **Accurate solids** (when the scene's solids are the paper's Q1): the equilibria of the solid
   methods again with Q2 elements on a coarser mesh (``ACCURATE_SOLIDS``, a third of the
   unknowns) and the SPEC section 7 rows built from equilibria recomputed with them: a row that
   fails with Q1 and passes with Q2 fails because of the Q1 mesh's locking (issue 13 item 5).
2. **Damping study, equilibria** (Sect. 4.3): every method at 1000 and 10000 rpm, c1..c3, relative
   and absolute damping models.
3. **Transients at paper settings** (Fig. 4, 6, 7): each method with its paper integrator and step
   at each speed, c3; histories per component, linear against nonlinear.
4. **Time-step study** (Fig. 5): 1000 rpm, c3, each method at half its paper step, the paper step
   and 1.2 times it; TLF also with the consistent mass at 1.2 times (the mass the paper's Eq. 29
   describes, whose central-difference limit lies between 1 and 1.2 times the paper step).
5. **Damping transients** (Fig. 8-11): GCMS (at the paper's 0.1 us), TLF and ANCF at 1000 and
   10000 rpm, c1..c3, both models.
6. **Efficiency spot check** (Sect. 4.2): time per step with and without system invariant
   matrices, for the SPEC section 7 row (the full tables are ``fxflex bench paper``).

Windows. The paper's text gives no time axes; ``PAPER_WINDOW`` (20 ms: more than one period of
the lowest, 60 Hz, mode at 1000 rpm and several at the higher speeds) is used for every method in
``--full`` and for all but TLF by default. TLF (27300 unknowns, a few ms per step) runs the
short ``TLF_WINDOWS`` by default: 2 ms for the speed transients (the load ramp and the first
response), 1 ms for the step study (a central-difference instability shows within tens of steps)
and 1 ms for the damping transients, which keeps the default run under 10 minutes on one core.
Runs that share everything but the window run once, over the longest window.

Outputs: ``report.md`` (rewritten after every study), ``steady.csv``, ``damping_steady.csv``,
``transients.csv`` (one summary row per run), ``paper.csv`` (SPEC section 7 rows),
``results.json``, ``series/*.csv`` (each run's samples, written as it runs) and the PNG figures.

This module runs the studies (:class:`Compare`); what they run is in
:mod:`~fxflex.analysis.compare_plan`, the formulations they share in
:mod:`~fxflex.analysis.compare_cache`, the SPEC section 7 rows in
:mod:`~fxflex.analysis.compare_paper`, the files in :mod:`~fxflex.analysis.compare_output` and
the figures in :mod:`~fxflex.analysis.compare_figures`.
"""


from __future__ import annotations

import math
import os
import time

import numpy as np

from fxflex.analysis import compare_figures as figures
from fxflex.analysis.compare_cache import FormCache
from fxflex.analysis.compare_output import transient_row, write_csv, write_results
from fxflex.analysis.compare_paper import not_applicable, paper_rows, paper_scene_differences
from fxflex.analysis.compare_plan import (ACCURATE_SOLIDS, C3, DAMPING_RPM, GROWTH_LIMIT,
                                          PAPER_WINDOW, SAMPLE_DT, TLF_WINDOWS, SteadyRow, plan,
                                          steady_time)
from fxflex.analysis.transient import Case, CaseResult, run_case, summarise
from fxflex.errors import FxflexError
from fxflex.formulation import PAPER_INTEGRATION, BuildOptions, build
from fxflex.io.payload import envelope
from fxflex.methods import formulation_class
from fxflex.scene import METHODS, PAPER_DAMPING, PAPER_RPM, Scene

__all__ = ["SteadyRow", "paper_rows", "run_compare", "plan", "steady_time", "PAPER_WINDOW",
           "TLF_WINDOWS", "SAMPLE_DT", "Compare", "FormCache"]

#: the figures of each transient study (:mod:`fxflex.analysis.compare_figures`)
FIGURES = {"speeds": figures.speeds, "steps": figures.steps, "damping": figures.damping}


# -- the study ----------------------------------------------------------------------------------

class Compare:
    """Runs the studies of the module docstring and writes their files (rank 0)."""

    def __init__(self, scene: Scene, methods, out_dir: str | None, comm, *, full: bool = False,
                 say=None, paper_window: float = PAPER_WINDOW, tlf_windows: dict | None = None,
                 accurate: dict | None = None):
        self.base = scene.replace(**{"rotation.profile": "constant"})
        #: what makes the scene another body than the paper's (issue 14): then every study runs
        #: as on the paper's scene and the paper's figures are marked not applicable
        self.differences = paper_scene_differences(self.base)
        self.paper_window, self.tlf_windows = paper_window, tlf_windows or TLF_WINDOWS
        self.methods = [m for m in METHODS if m in methods]
        self.out_dir, self.comm, self.full = out_dir, comm, full
        self.root = comm.rank == 0
        self._say = say
        self.forms = FormCache(self.base, comm)
        self.steady: list[SteadyRow] = []
        self.accurate_keys = ACCURATE_SOLIDS if accurate is None else accurate
        self.accurate: list[SteadyRow] = []     # study 1b: the solids' equilibria with Q2
        self.damping: list[SteadyRow] = []
        self.results: dict = {}             # Case.key -> CaseResult
        self.summaries: dict = {}           # (study, Case.key) -> summary dict
        self.costs: dict = {}               # method -> {"us_per_step", "build_s"}
        self.efficiency: dict = {}
        self.figures: list[str] = []
        self.timings: dict[str, float] = {}
        self.estimate: dict = {}
        self.t0 = time.perf_counter()
        self.load0 = os.getloadavg()[0]
        if out_dir and self.root:
            os.makedirs(os.path.join(out_dir, "series"), exist_ok=True)

    # -- helpers ------------------------------------------------------------------------------
    def say(self, text: str) -> None:
        if self._say is not None and self.root:
            self._say(text)

    def path(self, name: str) -> str | None:
        return os.path.join(self.out_dir, name) if self.out_dir else None

    def scene_for(self, rpm: float, c: float = C3, model: str = "relative") -> Scene:
        return self.forms.scene(rpm, c, model)

    def form(self, method: str, rpm: float, c: float = C3, model: str = "relative",
             mass: str | None = None):
        """The method for the scene at (rpm, c, model) (:class:`FormCache`: the small ones are
        kept and share what does not depend on the speed, a distributed one is rebuilt)."""
        return self.forms.get(method, rpm, c, model, mass)

    # -- steady states ------------------------------------------------------------------------
    def steady_row(self, method, rpm, c=C3, model="relative", stability: bool = True,
                   distributed_stability: bool = True) -> SteadyRow:
        """The equilibrium at (rpm, c, model) with what the report gives about it; the
        eigenvalue analysis (``stable``, ``growth_rate``, where offered) only if ``stability``,
        and for a distributed model (``form.distributed``) only if ``distributed_stability``."""
        t0 = time.perf_counter()
        form = self.form(method, rpm, c, model)
        st = form.steady_state()
        decide = (stability and st.converged
                  and (distributed_stability or not form.distributed))
        stable = form.stable(st) if decide else None             # None: undecided
        growth = float(form.growth_rate()[0]) if decide else None
        sig = torque = None
        t_st = steady_time(form.scene)
        if st.converged and form.root_stress is not None:
            sig = form.root_stress(t_st, st.q)
        if st.converged and form.extras is not None and form.steady_at_rest:
            # coordinates at rest in the rotating frame: q, q' = 0 (absolute coordinates move at
            # the equilibrium, GCMS's xi' = Omega J xi: not evaluated there)
            torque = float(form.extras(t_st, np.array(st.q, float), np.zeros(form.dof))[0])
        return SteadyRow(method=method, rpm=float(rpm), tip_m=np.asarray(st.tip, float),
                         stable=stable, converged=bool(st.converged), dof=int(form.dof),
                         seconds=time.perf_counter() - t0, c=float(c), model=model,
                         growth_rate=growth,
                         sigma_max=None if sig is None else float(np.max(sig)),
                         sigma_min=None if sig is None else float(np.min(sig)), torque=torque,
                         extra={"iterations": st.iterations})

    def probe(self, method: str) -> None:
        """Per-step cost of the method with the sampling of the studies (a short run)."""
        integ, dt = PAPER_INTEGRATION[method]
        t0 = time.perf_counter()
        form = self.form(method, PAPER_RPM[0])
        # a distributed model: a few ms per step, and rebuilt for every run (FormCache)
        n = 40 if form.distributed else 400
        build_s = time.perf_counter() - t0 if form.distributed else 0.0
        res = run_case(form, Case(method, PAPER_RPM[0], C3, "relative", integ, dt, n * dt),
                       sample_dt=SAMPLE_DT, csv_path=None, meta={}, enabled=False)
        self.costs[method] = {"us_per_step": 1e6 * res.wall_s / max(res.steps, 1),
                              "build_s": build_s}

    def run_steady(self) -> None:
        self.say("[1/6] steady states at 1000, 5000, 10000 rpm (c3, relative), stability, root "
                 "stress, per-step cost probes")
        t0 = time.perf_counter()
        for m in self.methods:
            for rpm in PAPER_RPM:
                row = self.steady_row(m, rpm)
                self.steady.append(row)
                self._log_steady(row)
                self._write_csv("steady.csv", [r.as_dict() for r in self.steady])
            self.probe(m)
        self.timings["steady"] = time.perf_counter() - t0
        self.run_accurate_solids()

    def solids(self) -> list[str]:
        return [m for m in self.methods if formulation_class(m).mesh_key == "mesh.solid"]

    def run_accurate_solids(self) -> None:
        """Study 1b (module docstring): the solid methods' equilibria with Q2 elements, when the
        scene's are Q1 (a Q2 scene's rows are already the accurate ones)."""
        if self.base.mesh.solid_degree != 1 or not self.solids() or not self.accurate_keys:
            return
        from fxflex.solid.model import solid_dof_count

        keys = self.accurate_keys
        self.say(f"[1b] accurate solids: equilibria with Q{keys['mesh.solid_degree']} on "
                 f"{list(keys['mesh.solid'])}, against which the Q1 mesh's rows are read")
        t0 = time.perf_counter()
        for m in self.solids():
            for rpm in PAPER_RPM:
                t1 = time.perf_counter()
                form = build(m, self.scene_for(rpm).replace(**keys), self.comm)
                st = form.steady_state()
                row = SteadyRow(method=m, rpm=float(rpm), tip_m=np.asarray(st.tip, float),
                                stable=None, converged=bool(st.converged),
                                dof=solid_dof_count(form.scene),
                                seconds=time.perf_counter() - t1)
                self.accurate.append(row)
                self._log_steady(row)
                del form
        self._write_csv("accurate_steady.csv", [r.as_dict() for r in self.accurate])
        self.timings["accurate_solids"] = time.perf_counter() - t0

    def accurate_rows(self) -> list[dict]:
        """The SPEC section 7 rows that equilibria decide, with the solids' equilibria from
        study 1b, each next to the same row of the scene's own mesh."""
        if not self.accurate:
            return []
        solids = {r.method for r in self.accurate}
        rows = [r for r in self.steady if r.method not in solids] + self.accurate
        own = {f["figure"]: f for f in paper_rows(self.steady)}
        out = []
        for f in paper_rows(rows):
            base = own.get(f["figure"])
            if base is None or (base["ours"] == f["ours"]):
                continue                    # a row without a solid in it
            out.append({**f, "q1_ours": base["ours"], "q1_pass": base["pass"],
                        "locking": bool(base["pass"] is False and f["pass"] is True)})
        return not_applicable(out) if self.differences else out

    def _log_steady(self, row: SteadyRow) -> None:
        t = 1e3 * row.tip_m
        sig = "" if row.sigma_max is None else \
            f"  sigma_X {row.sigma_max / 1e6:+.2f}/{row.sigma_min / 1e6:+.2f} MPa"
        extra = "" if (row.c, row.model) == (C3, "relative") else f" c={row.c:g} {row.model}"
        self.say(f"  {row.method:5s} {row.rpm:6g} rpm{extra}  {t[0]:+.5f} {t[1]:+.5f} "
                 f"{t[2]:+.5f} mm  stable={row.stable}{sig}  {row.seconds:.1f} s")

    def run_damping_steady(self) -> None:
        self.say("[2/6] damping study, equilibria: c1..c3, relative and absolute, "
                 f"{DAMPING_RPM[0]:g} and {DAMPING_RPM[1]:g} rpm")
        t0 = time.perf_counter()
        for m in self.methods:
            for rpm in DAMPING_RPM:
                for model in ("relative", "absolute"):
                    for c in PAPER_DAMPING:
                        # a distributed model's eigenvalue analysis (TLF: 27300 unknowns)
                        # only at the three speeds
                        row = self.steady_row(m, rpm, c, model, distributed_stability=False)
                        self.damping.append(row)
                        self._log_steady(row)
            self._write_csv("damping_steady.csv", [r.as_dict() for r in self.damping])
        self.timings["damping_steady"] = time.perf_counter() - t0
        if self.root and self.out_dir and self.damping:
            figures.damping_steady(self)

    # -- transients ---------------------------------------------------------------------------
    def schedule(self) -> tuple[dict, dict]:
        """(plan, runs): the cases of each study and, per shared key, the longest window."""
        cases = plan(self.methods, self.full, self.paper_window, self.tlf_windows)
        runs: dict = {}
        for study in ("speeds", "steps", "damping"):
            for c in cases[study]:
                if c.key not in runs or runs[c.key].t_end < c.t_end:
                    runs[c.key] = c
        return cases, runs

    def estimate_time(self) -> dict:
        """Seconds the remaining studies will take at most, from the probed per-step costs
        (runs that diverge stop early; TLF's consistent mass is counted at twice the lumped
        per-step cost)."""
        cases, runs = self.schedule()
        trans = 0.0
        for c in runs.values():
            cost = self.costs.get(c.method, {"us_per_step": 0.0, "build_s": 0.0})
            per = cost["us_per_step"] * (2.0 if c.mass == "consistent" else 1.0)
            trans += cost["build_s"] + 1e-6 * per * c.t_end / c.dt
        steady_per = {r.method: r.seconds for r in self.steady if r.rpm == PAPER_RPM[0]}
        damping = sum(steady_per.get(m, 0.0) for m in self.methods) * 3 * 2 * len(DAMPING_RPM)
        eff = 15.0 if "tlf" in self.methods else 3.0
        return {"transients_s": trans, "damping_steady_s": damping, "efficiency_s": eff,
                "runs": len(runs), "total_s": trans + damping + eff,
                "elapsed_s": time.perf_counter() - self.t0}

    def run_transients(self, study: str, runs: dict, cases: list[Case], index: str) -> None:
        titles = {"speeds": "transients at paper settings (Fig. 4, 6, 7)",
                  "steps": "time-step study (Fig. 5)",
                  "damping": "damping transients (Fig. 8-11)"}
        self.say(f"{index} {titles[study]}: {len(cases)} runs")
        t0 = time.perf_counter()
        for case in cases:
            run = runs[case.key]
            if case.key not in self.results:
                self.results[case.key] = self._run(run)
            res = self.results[case.key]
            steady = self.steady_of(case)
            s = summarise(res, case.t_end, None if steady is None else steady.tip_m,
                          None if steady is None else steady.growth_rate)
            self.summaries[(study, case.key)] = s
            self._log_case(s)
        if study == "steps":
            self._compare_steps(cases)
        self.timings[study] = time.perf_counter() - t0
        self._write_csv("transients.csv", [transient_row(study, s) for (study, _), s in
                                           self.summaries.items()])
        if self.root and self.out_dir:
            FIGURES[study](self, cases)

    def steady_of(self, case: Case) -> SteadyRow | None:
        for r in self.steady + self.damping:
            if (r.method, r.rpm, r.c, r.model) == (case.method, case.rpm, case.c, case.model):
                return r
        return None

    def _run(self, case: Case) -> CaseResult:
        """One transient; a run about an unstable equilibrium (eigenvalues) continues to
        ``GROWTH_LIMIT`` so that its growth is measured over decades (only the linear methods,
        whose response stays linear, get there)."""
        form = self.form(case.method, case.rpm, case.c, case.model, case.mass)
        path = self.path(os.path.join("series", case.name + ".csv"))
        meta = envelope(form.scene, method=case.method, integrator=case.integrator, dt_s=case.dt,
                        t_end_s=case.t_end, dof=form.dof, mass=case.mass)
        steady = self.steady_of(case)
        unstable = steady is not None and steady.stable is False and case.mass is None
        return run_case(form, case, sample_dt=SAMPLE_DT, csv_path=path, meta=meta,
                        enabled=self.root, limit=GROWTH_LIMIT if unstable else None)

    def _log_case(self, s: dict) -> None:
        c = s["case"]
        tail = (f"DIVERGED at {s['diverged']['time_s'] * 1e3:.3f} ms ({s['diverged']['cause']})"
                if s["diverged"] else "mean " + " ".join(f"{x:+.5f}" for x in s["hann_mean_mm"])
                + " mm" if s["hann_mean_mm"] else "")
        self.say(f"  {c['method']:5s} {c['rpm']:6g} rpm c={c['c']:g} {c['model']:8s} "
                 f"dt={c['dt'] * 1e6:.4g} us {c['t_end'] * 1e3:g} ms: {tail}  "
                 f"({s['wall_s']:.1f} s, {s['us_per_step']:.0f} us/step)")

    def _compare_steps(self, cases: list[Case]) -> None:
        """Each step's orthogonal deflection against the half step's, over the common window:
        max |difference| / peak of the half-step run (the paper's "close")."""
        for case in cases:
            ref = next((c for c in cases if c.method == case.method and c.mass is None
                        and math.isclose(c.dt, 0.5 * PAPER_INTEGRATION[c.method][1])), None)
            s = self.summaries[("steps", case.key)]
            s["vs_half"] = None
            if ref is None or ref is case or s["diverged"]:
                continue
            a = self.results[ref.key].window(case.t_end)
            b = self.results[case.key].window(case.t_end)
            a = a[a[:, 0] <= b[-1, 0]]                       # no extrapolation past b's end
            y = np.interp(a[:, 0], b[:, 0], b[:, 2])
            peak = np.max(np.abs(a[:, 2]))
            s["vs_half"] = float(np.max(np.abs(y - a[:, 2])) / peak) if peak > 0 else None

    # -- efficiency ---------------------------------------------------------------------------
    def run_efficiency(self, repeats: int = 3) -> None:
        """Time per step with and without system invariant matrices (Sect. 4.2): short runs, the
        best of ``repeats`` in process CPU time (on a shared machine wall time measures the other
        jobs too; the runs are single-threaded)."""
        from fxflex.time import simulate

        self.say("[6/6] efficiency spot check: system invariant matrices on/off")
        t0 = time.perf_counter()
        sc = self.scene_for(PAPER_RPM[0])
        routes = {"tlf": ("ufl", 20), "nebb": ("element", 5000), "ancf": ("element", 300)}
        for method, (without, steps) in routes.items():
            if method not in self.methods:
                continue
            integ, dt = PAPER_INTEGRATION[method]
            per = {}
            try:
                for fe in ("invariant", without):
                    form = build(method, sc, self.comm, BuildOptions(force_eval=fe,
                                                                     need_steady=False))
                    per[fe] = min(_cpu(simulate, form, integ, dt, steps * dt,
                                       sample_every=steps) for _ in range(repeats)) / steps
                    del form
            except FxflexError as exc:
                # a route this scene refuses (TLF's invariant matrices on Q2): no row, the
                # reason kept in the results and the report
                self.efficiency[method] = {"integrator": integ, "without": without,
                                           "skipped": str(exc)}
                self.say(f"  {method}: not measured: {exc}")
                continue
            self.efficiency[method] = {"integrator": integ, "without": without,
                                       "invariant_ms": 1e3 * per["invariant"],
                                       "without_ms": 1e3 * per[without],
                                       "ratio": per[without] / per["invariant"]}
            e = self.efficiency[method]
            self.say(f"  {method}: invariant {e['invariant_ms']:.3f} ms/step, {without} "
                     f"{e['without_ms']:.3f} ms/step, ratio {e['ratio']:.2f}")
        self.timings["efficiency"] = time.perf_counter() - t0

    # -- files --------------------------------------------------------------------------------
    def _write_csv(self, name: str, rows: list[dict]) -> None:
        if self.root and self.out_dir and rows:
            write_csv(self.path(name), rows)

    def result(self) -> dict:
        figures = paper_rows(self.steady, self.damping, self.summaries, self.efficiency)
        if self.differences:
            figures = not_applicable(figures)
        return {"methods": self.methods, "full": self.full,
                "paper_scene": not self.differences, "scene_differences": self.differences,
                "windows": {"paper_s": self.paper_window,
                            "tlf_s": None if self.full else self.tlf_windows,
                            "sample_dt_s": SAMPLE_DT},
                "steady": [r.as_dict() for r in self.steady],
                "accurate_solids": {"keys": {k: (list(v) if isinstance(v, tuple) else v)
                                             for k, v in self.accurate_keys.items()},
                                    "steady": [r.as_dict() for r in self.accurate],
                                    "paper": self.accurate_rows()} if self.accurate else None,
                "damping_steady": [r.as_dict() for r in self.damping],
                "transients": [{"study": st, **s} for (st, _), s in self.summaries.items()],
                "efficiency": self.efficiency, "paper": figures, "estimate": self.estimate,
                "costs": self.costs, "figures": list(self.figures),
                "timings_s": dict(self.timings), "load_average_start": self.load0,
                "seconds": time.perf_counter() - self.t0}

    def write(self, final: bool = False) -> dict:
        """results.json, paper.csv and report.md as they stand (rank 0)."""
        from fxflex.analysis.compare_report import render

        result = self.result()
        result["finished"] = final
        result["load_average_end"] = os.getloadavg()[0]
        report = render(self.base, result)
        if self.root and self.out_dir:
            write_results(self.out_dir, result, report)
        result["report"] = report
        return result

    def run(self) -> dict:
        self.run_steady()
        self.write()
        self.estimate = self.estimate_time()
        e = self.estimate
        self.say(f"estimate: the remaining studies take at most {e['total_s'] / 60:.1f} min "
                 f"({e['runs']} transient runs {e['transients_s']:.0f} s, damping equilibria "
                 f"{e['damping_steady_s']:.0f} s, efficiency {e['efficiency_s']:.0f} s; runs "
                 f"that diverge stop early), from the per-step costs measured just now: "
                 + ", ".join(f"{m} {c['us_per_step']:.0f} us" for m, c in self.costs.items()))
        self.run_damping_steady()
        self.write()
        cases, runs = self.schedule()
        for i, study in enumerate(("speeds", "steps", "damping")):
            self.run_transients(study, runs, cases[study], f"[{3 + i}/6]")
            self.write()
        self.run_efficiency()
        return self.write(final=True)


def _cpu(fn, *args, **kw) -> float:
    """Process CPU seconds of one call."""
    t0 = time.process_time()
    fn(*args, **kw)
    return time.process_time() - t0


def run_compare(scene: Scene, methods, out_dir: str | None, comm, progress=None, *,
                full: bool = False, **windows) -> dict:
    """The whole study (module docstring); ``progress(text)`` receives progress lines;
    ``windows``: ``paper_window`` and ``tlf_windows`` to shorten the runs, ``accurate`` the scene
    keys of study 1b ({} to skip it) (tests)."""
    return Compare(scene, methods, out_dir, comm, full=full, say=progress, **windows).run()
