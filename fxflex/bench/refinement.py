"""``fxflex bench convergence``: error against unknowns and CPU time for every method and variant
on the three cases of issue 13 (:mod:`fxflex.analysis.convergence`).

- (i) **default blade**, equilibrium at 1000 and 10000 rpm (``--quick``: 1000 rpm), against the
  stored converged reference (:mod:`fxflex.analysis.reference`) of the method's own continuum
  (FFRF, GCMS, LEBB: linear; TLF, NEBB, ANCF: the nonlinear one). Solids on Q1 and Q2 meshes
  of 16 to 128 layers (:data:`LEVELS_I`) and on the paper's 100 x 12 x 6 mesh,
  FFRF and GCMS with the scene's mode counts (their error includes the modal truncation); beams
  on 5 to 80 elements, both variants. A beam's error against a 3-D continuum levels off at the
  beam theory's own error: the beams are also measured against their own extrapolation
  (``error_self``).
- (ii) **slender spin-up** (transient, generalized-alpha at 1 ms): the in-plane and out-of-plane
  tip deflection at 2.5, 5 and 7.5 s of the beams on 5 to 80 elements (plus the finest at 0.5 ms,
  the step's share of the error), against the Richardson extrapolation of the locking-free
  variant's finest levels (the theory's converged answer, both variants share it). The solid
  methods are not run on it (a 10 m x 0.077 x 0.0052 m strip over 7.5 s: the report says why).
- (iii) **thin twisted cantilever** (static, unit tip force along Y and along Z), against the
  Richardson extrapolation of the full-order linear Q2 solutions on (12 k, 2 k, 2 k) hexahedra
  (the load is small enough that the linear and the nonlinear continua agree to 1e-6); the
  classical figures of MacNeal and Harder (1985), 5.424e-3 and 1.754e-3, are shown beside it.

Every row has the unknowns, the cost (build with caches bypassed + solve; CPU seconds of this
process, summed over ranks, and wall seconds) and the error |U - U_ref| / |U_ref| of the tip
deflection vector; the fitted order is the least-squares slope against h = 1 / (elements along
the span) over the finer levels. Rows are written to ``convergence.json`` as they are produced;
the tables (``convergence.md``), the choice "which discretisation for 1 %, 0.1 %" and log-log
plots of error against unknowns and against CPU time (``convergence_<case>.png``) at the end.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

from fxflex import cache
from fxflex.analysis import convergence as cases
from fxflex.analysis import reference as refmod
from fxflex.bench.accuracy import OWN_THEORY
from fxflex.bench.common import machine, markdown_table
from fxflex.errors import FxflexError
from fxflex.io.payload import jsonable
from fxflex.scene import Scene

__all__ = ["run", "MACNEAL_HARDER", "TARGETS"]

SOLIDS, BEAMS = ("ffrf", "gcms", "tlf"), ("lebb", "nebb", "ancf")
VARIANTS = {"lebb": ("paper",), "nebb": ("paper", "locking-free"),
            "ancf": ("paper", "locking-free")}
#: case (i): solid meshes per element degree (Y and Z divisions even: the centerline is a line
#: of nodes), beam element counts
LEVELS_I = {1: ((32, 4, 2), (64, 8, 4), (96, 12, 6), (128, 16, 8)),
            2: ((16, 2, 2), (32, 4, 2), (48, 6, 4), (64, 8, 4)), "beam": (5, 10, 20, 40, 80)}
QUICK_I = {1: ((32, 4, 2), (64, 8, 4)), 2: ((16, 2, 2),), "beam": (5, 10, 20)}
PAPER_MESH = (100, 12, 6)
#: case (ii): element counts, the step (s) and the finest level's check step
LEVELS_II, QUICK_II, DT_II, DT_CHECK = (5, 10, 20, 40, 80), (5, 10, 20), 1e-3, 5e-4
#: relative change of the finest levels below which a spin-up answer counts as settled
SETTLED = 1e-8
#: ANCF's cost per step grows fastest (about 10 ms at 40 elements): it stops at 40
MAX_II = {"ancf": 40}
#: case (iii): Q1 (24 k, 2 k, 2 k) and Q2 (12 k, 2 k, 2 k) levels k, beam element counts
LEVELS_III = {1: (1, 2, 3, 4, 6), 2: (1, 2, 3, 4), "beam": (5, 10, 20, 40, 80)}
QUICK_III = {1: (1, 2), 2: (1, 2), "beam": (5, 10, 20)}
#: MacNeal & Harder (1985), twisted beam, depth 0.32: tip deflection along the load (the Z force
#: acts in the plane of the tip section, the Y force across it)
MACNEAL_HARDER = {"Y": 1.754e-3, "Z": 5.424e-3}
TOLERANCES = (1e-2, 1e-3)
#: issue 13's targets, as the report states them
TARGETS = {
    "i": "FFRF, GCMS and TLF with Q2 within 0.3 % of the stored reference at a CPU cost no higher "
         "than the paper's Q1 mesh",
    "ii": "locking-free NEBB and ANCF within 1 % of the converged answer at 2.5, 5 and 7.5 s with "
          "10 elements",
    "iii": "Q2 within 1 % with at most a quarter of the unknowns Q1 needs for 1 %",
}


def _log(comm, text: str) -> None:
    if comm.rank == 0:
        print(f"[bench convergence] {text}", flush=True)


def _cpu(comm) -> float:
    """CPU seconds of this process summed over the ranks (collective)."""
    return comm.allreduce(time.process_time())


class _Cost:
    """CPU (summed over ranks) and wall seconds of a block; collective."""

    def __init__(self, comm):
        self.comm = comm

    def __enter__(self):
        self.comm.Barrier()
        self.cpu0, self.wall0 = _cpu(self.comm), time.perf_counter()
        return self

    def __exit__(self, *exc):
        if exc[0] is None:
            self.cpu, self.wall = _cpu(self.comm) - self.cpu0, time.perf_counter() - self.wall0


def _error(tip, ref) -> float:
    return refmod.relative_error(np.asarray(tip, float), np.asarray(ref, float))


def _label(method: str, variant: str = "", degree: int = 0) -> str:
    if degree:
        return f"{method} Q{degree}"
    return method if variant in ("", "paper") and method == "lebb" else f"{method} {variant}"


def _steady(method: str, scene: Scene, comm) -> tuple[int, np.ndarray, float, float, bool]:
    """(unknowns, tip, CPU s, wall s, converged) of a steady state built from nothing; for FFRF
    and GCMS the unknowns of the solid mesh their modes are computed on."""
    from fxflex.formulation import build
    from fxflex.solid.model import solid_dof_count

    with _Cost(comm) as cost:
        with cache.bypass():
            form = build(method, scene, comm)
        st = form.steady_state()
    # FFRF, GCMS: the mesh's unknowns, not the modes' count
    dof = solid_dof_count(scene) if method in SOLIDS else form.dof
    return dof, np.asarray(st.tip, float), cost.cpu, cost.wall, bool(st.converged)


def _measure(store: "_Store", method: str, scene: Scene, comm, ref, **ident) -> dict:
    """One level's steady state as a stored row: ``ident`` (case, level, ...), unknowns, cost,
    tip and its error against ``ref``."""
    dof, tip, cpu, wall, ok = _steady(method, scene, comm)
    return store.add({**ident, "method": method, "dof": dof, "cpu_s": cpu, "wall_s": wall,
                      "tip_m": tip.tolist(), "converged": ok, "error": _error(tip, ref)})


def _extrapolated(n, tips) -> np.ndarray:
    """Per-component Richardson on the three finest levels (the finest value where the
    differences do not decay monotonically)."""
    tips = np.asarray(tips, float)
    ext = refmod.extrapolate(list(n), tips)["extrapolated_m"]
    return np.array([tips[-1, k] if v is None else v for k, v in enumerate(ext)])


def _order(rows: list[dict], key: str) -> float | None:
    """Fitted order of ``key`` over the three finest levels of a family that have a non-zero
    value (None with fewer than two). For ``error_self`` (against the family's own Richardson
    extrapolation from the same three levels) it is the Richardson order, not an independent
    measurement."""
    pts = [(r["n"], r[key]) for r in rows if r.get(key)]
    if len(pts) < 2:
        return None
    pts = pts[-3:]
    return cases.fitted_order([p[0] for p in pts], [p[1] for p in pts])


class _Store:
    """Rows appended as they are produced; the JSON file rewritten atomically each time."""

    def __init__(self, path: str, comm, info: dict):
        self.path, self.comm, self.data = path, comm, {"info": info, "rows": []}

    def add(self, row: dict) -> dict:
        self.data["rows"].append(row)
        self.save()
        return row

    def save(self) -> None:
        if self.comm.rank != 0:
            return
        tmp = self.path + ".tmp"
        with open(tmp, "w") as fh:
            json.dump(jsonable(self.data), fh, indent=1)
        os.replace(tmp, self.path)


# -- case (i) ------------------------------------------------------------------------------------
def case_i(comm, store: _Store, quick: bool, log) -> None:
    base = cases.default_blade()
    ref = refmod.stored_reference(base)
    if ref is None:
        raise FxflexError("bench convergence: fxflex/data/reference.json does not hold the "
                          "default scene's reference (run fxflex bench accuracy --reference)")
    levels = QUICK_I if quick else LEVELS_I
    speeds = (1000.0,) if quick else (1000.0, 10000.0)
    for rpm in speeds:
        def reference(method):
            return ref["theories"][OWN_THEORY[method]][f"{rpm:g}"]["reference_m"]

        for method in SOLIDS:
            meshes = [(d, i + 1, div) for d in (1, 2) for i, div in enumerate(levels[d])]
            if not quick:
                meshes.append((1, "paper", PAPER_MESH))
            for degree, m, div in meshes:
                sc = cases.default_blade(rpm, {"solid": div, "solid_degree": degree})
                row = _measure(store, method, sc, comm, reference(method), case="i", rpm=rpm,
                               variant="", degree=degree, level=m, mesh=list(div), n=div[0])
                log(f"(i) {rpm:g} rpm {method} Q{degree} {list(div)}: {row['dof']} dof, error "
                    f"{100 * row['error']:.4f} %, {row['cpu_s']:.2f} CPU s")
        for method in BEAMS:
            for variant in VARIANTS[method]:
                rows = []
                for n in levels["beam"]:
                    sc = cases.default_blade(rpm, {"beam_elements": n, "beam_variant": variant})
                    rows.append(_measure(store, method, sc, comm, reference(method), case="i",
                                         rpm=rpm, variant=variant, degree=0, level=n, n=n))
                _self_errors(rows, store)
                log(f"(i) {rpm:g} rpm {_label(method, variant)}: errors "
                    + ", ".join(f"{r['n']} el {100 * r['error']:.3f} %" for r in rows)
                    + f" (self: {100 * rows[-2]['error_self']:.2g} % at {rows[-2]['n']})")


def _self_errors(rows: list[dict], store: _Store) -> None:
    """Each level's error against the family's own extrapolation (own continuum)."""
    if len(rows) < 3:
        return
    ext = _extrapolated([r["n"] for r in rows], [r["tip_m"] for r in rows])
    for r in rows:
        r["self_reference_m"] = ext.tolist()
        r["error_self"] = _error(r["tip_m"], ext)
    store.save()


# -- case (ii) -----------------------------------------------------------------------------------
def _spinup(method: str, n: int, variant: str, dt: float, t_end: float, comm) -> dict:
    from fxflex.api import run
    from fxflex.formulation import build

    times = [t for t in cases.SPINUP_TIMES if t <= t_end + 1e-12]
    got: dict[float, list] = {}

    def on_sample(t, tip, extras, q):
        for target in times:
            if abs(t - target) < 0.25 * dt:
                got[target] = [float(x) for x in tip]

    sc = cases.slender_spinup({"beam_elements": n, "beam_variant": variant})
    with _Cost(comm) as cost:
        with cache.bypass():
            form = build(method, sc, comm)
        res = run(form, t_end, integrator="generalized-alpha", dt=dt, sample_dt=0.5,
                  on_sample=on_sample, diagnose=False)
    return {"dof": form.dof, "cpu_s": cost.cpu, "wall_s": cost.wall, "steps": res.steps,
            "ms_per_step": 1e3 * cost.wall / max(res.steps, 1),
            "diverged": None if res.diverged is None else res.diverged.get("reason"),
            "tips": {f"{t:g}": got.get(t) for t in times}}


def case_ii(comm, store: _Store, quick: bool, log) -> None:
    levels = QUICK_II if quick else LEVELS_II
    t_end = 2.5 if quick else max(cases.SPINUP_TIMES)
    families = {}
    for method in BEAMS:
        for variant in VARIANTS[method]:
            rows = []
            mine = [n for n in levels if n <= MAX_II.get(method, n)]
            for n in mine:
                r = _spinup(method, n, variant, DT_II, t_end, comm)
                rows.append(store.add({"case": "ii", "method": method, "variant": variant,
                                       "n": n, "dt_s": DT_II, **r}))
                log(f"(ii) {_label(method, variant)} {n} el: in-plane tip "
                    + ", ".join(f"{t} s {1e3 * v[1]:.4f} mm" for t, v in r["tips"].items()
                                if v is not None)
                    + f"; {r['ms_per_step']:.3f} ms/step")
            if not quick:
                r = _spinup(method, mine[-1], variant, DT_CHECK, t_end, comm)
                store.add({"case": "ii", "method": method, "variant": variant,
                           "n": mine[-1], "dt_s": DT_CHECK, "step_check": True, **r})
            families[(method, variant)] = rows
    # the converged answer of each theory: its locking-free (LEBB: only) variant, extrapolated
    refs = {m: spinup_reference(families[(m, VARIANTS[m][-1])]) for m in BEAMS}
    store.data.setdefault("references", {}).update({f"ii-{m}": r for m, r in refs.items()})
    spinup_errors(store.data["rows"], refs)
    store.save()


def spinup_reference(best: list[dict]) -> dict:
    """A theory's converged spin-up answer at each time: Richardson on its finest three levels,
    or None at a time where the in-plane differences do not shrink monotonically (ANCF's
    lateral-torsional buckling of the strip grows from round-off on fine meshes,
    docs/beams.md: there is no converged answer to extrapolate)."""
    ref = {}
    for t in best[-1]["tips"]:
        tips = [r["tips"][t] for r in best]
        if any(v is None for v in tips):
            continue
        n = [r["n"] for r in best]
        f = [v[1] for v in tips[-3:]]
        p, _ = refmod.richardson(1.0 / np.asarray(n[-3:], float), f)
        if p is not None:
            ref[t] = _extrapolated(n, tips).tolist()
        elif abs(f[2] - f[1]) <= SETTLED * abs(f[2]):     # settled to round-off
            ref[t] = list(tips[-1])
        else:
            ref[t] = None
    return ref


def spinup_errors(rows: list[dict], refs: dict) -> None:
    """Each (ii) row's errors against its theory's reference and against NEBB's; ``error`` is
    the worst over the times, taking NEBB's answer where ANCF has none (its buckling; without
    it the two nonlinear theories agree to 1e-4 here, LEBB's linear one does not)."""
    for r in rows:
        if r["case"] != "ii" or r["method"] not in refs:
            continue
        ref, nebb = refs[r["method"]], refs.get("nebb", {})
        r["reference_m"] = ref
        r["errors"] = {t: (None if r["tips"].get(t) is None or v is None else
                           _error(r["tips"][t], v)) for t, v in ref.items()}
        r["errors_vs_nebb"] = {t: (None if r["tips"].get(t) is None or v is None else
                                   _error(r["tips"][t], v)) for t, v in nebb.items()}
        # the worst time; where the theory has no converged answer, the error against NEBB's
        fallback = r["errors_vs_nebb"] if r["method"] == "ancf" else {}
        worst = [r["errors"].get(t) if r["errors"].get(t) is not None else
                 fallback.get(t) for t in r["tips"]]
        finite = [e for e in worst if e is not None]
        r["error"] = max(finite) if finite else None


# -- case (iii) ----------------------------------------------------------------------------------
def _twisted_divisions(degree: int, k: int) -> tuple[int, int, int]:
    return (24 * k if degree == 1 else 12 * k), 2 * k, 2 * k


def case_iii(comm, store: _Store, quick: bool, log) -> None:
    from fxflex.solid.model import SolidModel
    from fxflex.solid.small_strain import linear_steady

    levels = QUICK_III if quick else LEVELS_III
    for direction in ("Y", "Z"):
        # the converged linear continuum: full-order Q2, Richardson on the finest three levels
        rows = []
        for k in levels[2]:
            div = _twisted_divisions(2, k)
            sc = cases.thin_twisted(direction, {"solid": div, "solid_degree": 2})
            with _Cost(comm) as cost:
                with cache.bypass():
                    model = SolidModel(sc, comm, divisions=div, degree=2)
                st = linear_steady(model)
            rows.append({"n": div[0], "tip_m": np.asarray(st.tip, float).tolist(),
                         "dof": model.dof, "cpu_s": cost.cpu})
        ref = (_extrapolated([r["n"] for r in rows], [r["tip_m"] for r in rows])
               if len(rows) >= 3 else np.asarray(rows[-1]["tip_m"]))
        store.data.setdefault("references", {})[f"iii-{direction}"] = {
            "reference_m": ref.tolist(), "levels": rows, "macneal_harder_m":
            MACNEAL_HARDER[direction], "estimate": (
                _error(rows[-1]["tip_m"], ref) if len(rows) >= 3 else None)}
        log(f"(iii) {direction}: converged tip {ref.tolist()} (MacNeal-Harder "
            f"{MACNEAL_HARDER[direction]:g} along the force)")
        for method in SOLIDS:
            for degree in (1, 2):
                for k in levels[degree]:
                    div = _twisted_divisions(degree, k)
                    sc = cases.thin_twisted(direction, {"solid": div, "solid_degree": degree})
                    row = _measure(store, method, sc, comm, ref, case="iii",
                                   direction=direction, variant="", degree=degree, level=k,
                                   mesh=list(div), n=div[0])
                    log(f"(iii) {direction} {method} Q{degree} {list(div)}: {row['dof']} dof, "
                        f"error {100 * row['error']:.3f} %")
        for method in BEAMS:
            for variant in VARIANTS[method]:
                fam = []
                for n in levels["beam"]:
                    sc = cases.thin_twisted(direction, {"beam_elements": n,
                                                        "beam_variant": variant})
                    fam.append(_measure(store, method, sc, comm, ref, case="iii",
                                        direction=direction, variant=variant, degree=0,
                                        level=n, n=n))
                _self_errors(fam, store)
                log(f"(iii) {direction} {_label(method, variant)}: "
                    + ", ".join(f"{r['n']} el {100 * r['error']:.3f} %" for r in fam))


# -- the report ----------------------------------------------------------------------------------
def _families(rows: list[dict]) -> dict:
    out: dict = {}
    for r in rows:
        if r.get("step_check"):
            continue
        where = {"i": f"{r.get('rpm', 0):g} rpm", "ii": "spin-up",
                 "iii": f"tip force {r.get('direction')}"}[r["case"]]
        key = (r["case"], where, r["method"], r["variant"],
               r.get("degree", 0), r.get("level") == "paper")
        out.setdefault(key, []).append(r)
    return out


def cheapest(rows: list[dict], tol: float, key: str = "error") -> dict | None:
    """The cheapest (CPU) row whose ``key`` error is at most ``tol``."""
    ok = [r for r in rows if r.get(key) is not None and r[key] <= tol]
    return min(ok, key=lambda r: r["cpu_s"]) if ok else None


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.3g} %"


def _where(r: dict | None) -> str:
    if r is None:
        return "not reached"
    what = f"{r['mesh']}" if "mesh" in r else f"{r['n']} el"
    return f"{what} ({r['dof']} dof, {r['cpu_s']:.2g} s)"


def report(data: dict) -> tuple[str, dict]:
    rows = data["rows"]
    fams = _families(rows)
    lines = ["# fxflex bench convergence", "",
             f"Machine: {data['info']['machine']}; ranks {data['info']['ranks']}; "
             f"{'quick (smoke) levels' if data['info']['quick'] else 'full levels'}.", "",
             "Error: |U - U_ref| / |U_ref| of the tip deflection vector; cost: CPU s (build with "
             "caches bypassed + solve, summed over ranks). Order: least-squares slope against "
             "1 / (elements along the span) over the three finest levels.", ""]
    titles = {"i": "(i) Default blade, equilibrium, against the stored converged reference of "
                   "the method's own continuum",
              "ii": "(ii) Slender spin-up, transient, against the theory's converged answer "
                    "(worst of 2.5 / 5 / 7.5 s; NEBB's where the theory has none)",
              "iii": "(iii) Thin twisted cantilever, static, against the converged Q2 solid"}
    choice: dict = {}
    for case in ("i", "ii", "iii"):
        table = []
        for key, fam in fams.items():
            if key[0] != case:
                continue
            name = _label(key[2], key[3], key[4]) + (" paper mesh" if key[5] else "")
            where = key[1]
            order = None if key[5] else _order(fam, "error")
            self_order = None if key[5] else _order(fam, "error_self")
            for r in fam:
                table.append([where, name, r.get("mesh", r["n"]), r["dof"], f"{r['cpu_s']:.3g}",
                              _pct(r.get("error")), _pct(r.get("error_self"))])
            table.append([where, name, "fitted order", "", "",
                          "-" if order is None else f"{order:.2f}",
                          "-" if self_order is None else f"{self_order:.2f}"])
            # the discretisation error: a beam against its own theory's extrapolation in (i)
            # and (iii) (its error against the solid levels off at the beam theory's error)
            disc = "error_self" if key[2] in BEAMS and case != "ii" else "error"
            pick = {f"{tol:g}": _where(cheapest(fam, tol, disc)) for tol in TOLERANCES}
            choice.setdefault(case, {}).setdefault(where, {})[name] = pick
        if not table:
            continue
        lines += [f"## {titles[case]}", "", f"Target: {TARGETS[case]}.", "",
                  markdown_table(["where", "method", "level", "dof", "CPU s", "error",
                                  "error vs own extrapolation"], table)]
        if case == "ii":
            lines += _spinup_detail(rows)
        if case == "iii":
            for d, ref in sorted(data.get("references", {}).items()):
                if not d.startswith("iii-"):
                    continue
                lines.append(f"- {d}: converged tip {['%.6e' % x for x in ref['reference_m']]} "
                             f"m (estimated error of the finest Q2 level "
                             f"{_pct(ref['estimate'])}); MacNeal-Harder along the force "
                             f"{ref['macneal_harder_m']:g}")
            lines.append("")
    lines += ["## Which discretisation for 1 %, 0.1 %", "",
              "The cheapest level measured whose discretisation error meets each tolerance: "
              "for the solids and in (ii) the error above; for the beams in (i) and (iii) the "
              "error against their own theory's extrapolation (against the 3-D continuum a "
              "beam levels off at its theory's error, the 'error' column).", ""]
    table = []
    for case, per in choice.items():
        for where, methods in per.items():
            for name, pick in methods.items():
                table.append([case, where, name, pick["0.01"], pick["0.001"]])
    lines.append(markdown_table(["case", "where", "method", "1 %", "0.1 %"], table))
    return "\n".join(lines) + "\n", choice


def _spinup_detail(rows: list[dict]) -> list[str]:
    table = []
    for r in rows:
        if r["case"] != "ii":
            continue
        tips = [("-" if r["tips"].get(t) is None else f"{1e3 * r['tips'][t][1]:.4f}")
                for t in ("2.5", "5", "7.5")]
        errs = [_pct((r.get("errors") or {}).get(t)) for t in ("2.5", "5", "7.5")]
        nebb = [_pct((r.get("errors_vs_nebb") or {}).get(t)) for t in ("2.5", "5", "7.5")]
        table.append([_label(r["method"], r["variant"]), r["n"], f"{1e3 * r['dt_s']:g}",
                      *tips, *errs, " / ".join(nebb), f"{r['ms_per_step']:.3f}",
                      r.get("diverged") or ""])
    return ["In-plane tip W_Y (mm) and errors at 2.5 / 5 / 7.5 s against the theory's own "
            "converged answer ('-': none, the finest levels' differences do not shrink), and "
            "against NEBB's:", "",
            markdown_table(["method", "el", "dt ms", "2.5 s", "5 s", "7.5 s", "err 2.5",
                            "err 5", "err 7.5", "vs NEBB 2.5 / 5 / 7.5", "ms/step",
                            "stopped"], table),
            "The solid methods are not run on (ii): the strip is 0.0052 m thick and 10 m long; "
            "a Q2 mesh that resolves its bending has about 1e4 unknowns and a 7.5 s "
            "generalized-alpha run at 1 ms is 7500 factorised Newton steps (hours for TLF), "
            "and FFRF/GCMS with clamped modes lack the geometric stiffening of the spin-up.", ""]


def plot(data: dict, out_dir: str) -> list[str]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    fams = _families(data["rows"])
    for case in ("i", "ii", "iii"):
        keys = [k for k in fams if k[0] == case and not k[5]]
        if not keys:
            continue
        wheres = sorted({k[1] for k in keys}, key=lambda w: (len(w), w))
        fig, axes = plt.subplots(len(wheres), 2, figsize=(11, 4.2 * len(wheres)), squeeze=False)
        for i, where in enumerate(wheres):
            for key in (k for k in keys if k[1] == where):
                pts = [(r["dof"], r["cpu_s"], r["error"]) for r in fams[key]
                       if r.get("error")]
                if not pts:
                    continue
                dof, cpu, err = zip(*pts)
                name = _label(key[2], key[3], key[4])
                # one colour per method; dashed: the paper's element (Q1, paper variant)
                style = dict(ls="--" if key[3] == "paper" or key[4] == 1 else "-",
                             color=f"C{(SOLIDS + BEAMS).index(key[2])}", marker="o", ms=3,
                             label=name)
                axes[i, 0].loglog(dof, err, **style)
                axes[i, 1].loglog(cpu, err, **style)
            title = where
            axes[i, 0].set(xlabel="unknowns", ylabel="relative tip error",
                           title=f"({case}) {title}")
            axes[i, 1].set(xlabel="CPU s", ylabel="relative tip error", title=f"({case}) {title}")
            for ax in axes[i]:
                for tol in TOLERANCES:
                    ax.axhline(tol, color="0.6", lw=0.6)
                ax.grid(True, which="both", lw=0.3)
            axes[i, 1].legend(fontsize=7)
        fig.tight_layout()
        path = os.path.join(out_dir, f"convergence_{case}.png")
        fig.savefig(path + ".tmp.png", dpi=110)
        plt.close(fig)
        os.replace(path + ".tmp.png", path)
        written.append(path)
    return written


def run(scene: Scene, out_dir: str, comm, quick: bool = False) -> dict:
    """Run the three cases (the scene is not used: the cases are fixed, issue 13), write the
    JSON rows as they come, then the report and the plots."""
    def log(text):
        _log(comm, text)

    info = {"machine": machine(), "load_start": os.getloadavg()[0], "ranks": comm.size,
            "quick": quick}
    store = _Store(os.path.join(out_dir, "convergence.json"), comm, info)
    t0 = time.perf_counter()
    for name, case in (("i", case_i), ("iii", case_iii), ("ii", case_ii)):
        log(f"case ({name})")
        case(comm, store, quick, log)
    info.update(load_end=os.getloadavg()[0], wall_s=time.perf_counter() - t0)
    text, choice = report(store.data)
    store.data["choice"] = choice
    store.save()
    if comm.rank == 0:
        with open(os.path.join(out_dir, "convergence.md"), "w") as fh:
            fh.write(text)
        plot(store.data, out_dir)
    summary = [f"bench convergence: {len(store.data['rows'])} levels in {info['wall_s']:.0f} s"]
    for case, per in choice.items():
        for where, methods in per.items():
            best = {n: p["0.01"] for n, p in methods.items()}
            summary.append(f"  ({case}) {where}: 1 % with " + "; ".join(
                f"{n}: {w}" for n, w in best.items()))
    return {"summary": "\n".join(summary) + f"\n(tables in {out_dir}/convergence.md)",
            "info": info, "choice": choice}
