"""``fxflex bench airfoil``: the six methods on a NACA 2412 blade at 1000 and 5000 rpm, each
against its own converged reference (issue 14, validation).

The blade: the scene's length, chord (``root_y`` -> ``tip_y``), twist and load with section
``naca4`` 2412 (when the scene's section is the paper's rectangle; another non-rectangular scene
is taken as given). The thickness follows the chord (12 %), so the blade is slender (L / chord
8.3 to 12.5) and flexible across the chord: under the paper's line load its tip deflects about
12 % of its length at 1000 rpm.

Per method and speed, the steady state (SPEC section 6) at three refinements -- the solids
(FFRF, GCMS, TLF) on 27-node hexahedra (``mesh.solid_degree = 2``) (10 m, 4 m, 2 m) for m = 1,
2, 3, the beams (LEBB, NEBB, ANCF, the scene's ``mesh.beam_variant``) on 20, 40, 80 elements --
then per component Richardson's extrapolation and the observed order
(:func:`fxflex.analysis.reference.richardson`, h = 1 / m or 1 / elements): each method's own
converged reference, the continuum of its own theory. Each level's stability verdict is the
eigenvalue analysis about its steady state (``form.stable``; ``growth_rate``: the largest real
part, the slowest-decaying or fastest-growing mode).

The six side by side: the references, and the model gaps between theories (beam against solid:
LEBB against FFRF for the small-strain theory, NEBB and ANCF against TLF for the nonlinear one;
GCMS against FFRF, the same theory in other coordinates).

Diagnosis of an earlier observation (TLF -0.125 m against NEBB -0.108 m at 1000 rpm): NEBB on
the scene's 10 elements and TLF on Q2 20 x 8 x 2 are measured against their references, and the
remaining gap between the converged NEBB and TLF is measured again with the load scaled by
``SMALL_LOAD``: a gap that stays (relative) is linear beam theory's (the section, the load's
offset from the shear centre, shear), one that vanishes is geometric nonlinearity.

Results are written as they are produced (``airfoil.json``, rewritten after every solve), then
``airfoil.md``. ``--quick``: coarse levels (seconds), for the test.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

from fxflex.analysis.reference import relative_error, richardson
from fxflex.bench.common import machine, markdown_table
from fxflex.formulation import build
from fxflex.io.payload import jsonable
from fxflex.scene import METHODS, Scene

__all__ = ["run", "blade", "levels", "reference", "SPEEDS"]

SPEEDS = (1000.0, 5000.0)
SOLIDS = ("ffrf", "gcms", "tlf")
#: refinement levels m of each family: solids (10 m, 4 m, 2 m) Q2, beams elements
LEVELS = {"solid": (1, 2, 3), "beam": (20, 40, 80)}
#: --quick: the solids refined along the span only, (4 m, 4, 2)
QUICK_LEVELS = {"solid": (1, 2, 3), "beam": (4, 8, 16)}
SMALL_LOAD = 0.01
COMPONENTS = ("longitudinal", "orthogonal", "load")


def blade(scene: Scene) -> Scene:
    """The benchmark's blade: the scene with a NACA 2412 section unless it has its own shape."""
    if scene.geometry.section != "rectangle":
        return scene
    return scene.replace(**{"geometry.section": "naca4", "geometry.airfoil": "2412"})


def levels(method: str, quick: bool) -> list[tuple[int, dict]]:
    """(h^-1, scene keys) of each refinement level of ``method``, coarse to fine."""
    table = QUICK_LEVELS if quick else LEVELS
    if method in SOLIDS:
        return [(m, {"mesh.solid_degree": 2,
                     "mesh.solid": (4 * m, 4, 2) if quick else (10 * m, 4 * m, 2 * m)})
                for m in table["solid"]]
    return [(n, {"mesh.beam_elements": n}) for n in table["beam"]]


def reference(rows: list[dict]) -> dict:
    """Richardson per component over the three levels (``rows`` coarse to fine, ``n`` = h^-1):
    the extrapolated tip, the observed order and each level's error against it; a component
    whose differences change sign keeps the finest value (order None)."""
    n = [r["n"] for r in rows]
    tips = np.array([r["tip_m"] for r in rows], float)
    ext, order = [], []
    for k in range(3):
        p, v = richardson([1.0 / x for x in n], tips[:, k]) if len(rows) == 3 else (None, None)
        ext.append(float(tips[-1, k]) if v is None else v)
        order.append(p)
    ext = np.array(ext)
    return {"tip_m": ext.tolist(), "order": order,
            "errors": [relative_error(t, ext) for t in tips],
            "estimate": float(np.linalg.norm(tips[-1] - ext) / np.linalg.norm(ext))}


class _Store:
    """The rows as they are produced; ``airfoil.json`` rewritten atomically after each."""

    def __init__(self, path: str, comm, info: dict):
        self.path, self.comm = path, comm
        self.data = {"info": info, "rows": [], "diagnosis": []}

    def add(self, key: str, row: dict) -> dict:
        self.data[key].append(row)
        self.save()
        return row

    def save(self) -> None:
        if self.comm.rank != 0 or not self.path:
            return
        tmp = self.path + ".tmp"
        with open(tmp, "w") as fh:
            json.dump(jsonable(self.data), fh, indent=1)
        os.replace(tmp, self.path)


def _solve(method: str, scene: Scene, comm, stability: bool = True, form=None) -> tuple:
    """(row, form): the steady state, its unknowns and times, and the stability verdict about
    it (the largest real part of the linearised rotating system's eigenvalues)."""
    t0 = time.perf_counter()
    form = form if form is not None else build(method, scene, comm)
    st = form.steady_state()
    t1 = time.perf_counter()
    stable = growth = None
    if stability and st.converged:
        stable = form.stable(st)
        growth = float(form.growth_rate()[0]) if stable is not None else None
    if method in SOLIDS:
        from fxflex.solid.model import solid_dof_count

        dof = solid_dof_count(form.scene)
    else:
        dof = int(form.dof)
    return ({"dof": dof, "tip_m": np.asarray(st.tip, float).tolist(),
             "converged": bool(st.converged), "stable": stable, "growth_rate": growth,
             "steady_s": t1 - t0, "stability_s": time.perf_counter() - t1}, form)


def _log(comm, text: str) -> None:
    if comm.rank == 0:
        import sys

        sys.stderr.write(text + "\n")
        sys.stderr.flush()


def _levels_study(store: _Store, base: Scene, comm, methods, quick: bool, log) -> None:
    for method in methods:
        for n, keys in levels(method, quick):
            form = None
            for rpm in SPEEDS:
                sc = base.replace(**keys, **{"rotation.rpm": rpm})
                # FFRF and GCMS move to the next speed keeping their mesh, modes and projections
                reuse = form.at(rpm=rpm) if form is not None and method in ("ffrf", "gcms") \
                    else None
                row, f = _solve(method, sc, comm, form=reuse)
                if method in ("ffrf", "gcms") and form is None:
                    form = f
                del f
                row = store.add("rows", {"method": method, "rpm": rpm, "n": n,
                                         "mesh": {k: (list(v) if isinstance(v, tuple) else v)
                                                  for k, v in keys.items()}, **row})
                log(f"  {method:5s} {rpm:6g} rpm  level {n:3d}  dof {row['dof']:7d}  tip "
                    + " ".join(f"{1e3 * x:+.4f}" for x in row["tip_m"]) + " mm  stable="
                    f"{row['stable']} (max Re {row['growth_rate']})  {row['steady_s']:.1f} + "
                    f"{row['stability_s']:.1f} s")
            del form


def _diagnosis(store: _Store, base: Scene, comm, quick: bool, log) -> None:
    """The earlier session's pair (NEBB on the scene's beam mesh, TLF on Q2 20 x 8 x 2) at
    1000 rpm, and the converged-theory gap at the full and a small load (module docstring)."""
    rpm = SPEEDS[0]
    fine_beam = levels("nebb", quick)[-1][0]
    solid_keys = levels("tlf", quick)[1][1]
    cases = [("nebb", "the scene's beam mesh", 1.0, {}),
             ("tlf", "Q2 20 x 8 x 2", 1.0, {"mesh.solid_degree": 2, "mesh.solid":
                                           (8, 4, 2) if quick else (20, 8, 2)}),
             ("nebb", f"{fine_beam} elements, small load", SMALL_LOAD,
              {"mesh.beam_elements": fine_beam}),
             ("tlf", "level 2, small load", SMALL_LOAD, solid_keys),
             ("nebb", f"{fine_beam} elements, locking-free", 1.0,
              {"mesh.beam_elements": fine_beam, "mesh.beam_variant": "locking-free"}),
             ("ancf", f"{fine_beam} elements, locking-free", 1.0,
              {"mesh.beam_elements": fine_beam, "mesh.beam_variant": "locking-free"})]
    for method, label, scale, keys in cases:
        sc = base.replace(**keys, **{"rotation.rpm": rpm,
                                     "load.line_load": scale * base.load.line_load,
                                     "load.tip_force": tuple(scale * f for f in
                                                             base.load.tip_force)})
        row, form = _solve(method, sc, comm, stability=False)
        del form
        store.add("diagnosis", {"method": method, "case": label, "load_scale": scale, "rpm": rpm,
                                **row})
        log(f"  diagnosis {method} {label}: tip "
            + " ".join(f"{1e3 * x:+.4f}" for x in row["tip_m"]) + " mm")


def _by(rows, method, rpm):
    return sorted((r for r in rows if (r["method"], r["rpm"]) == (method, rpm)),
                  key=lambda r: r["n"])


def assemble(data: dict) -> dict:
    """References, side-by-side gaps and the diagnosis from the stored rows."""
    rows = data["rows"]
    refs = {}
    for rpm in SPEEDS:
        for m in METHODS:
            lv = _by(rows, m, rpm)
            if len(lv) == 3:
                refs[f"{m}@{rpm:g}"] = {**reference(lv), "method": m, "rpm": rpm,
                                        "stable": [r["stable"] for r in lv],
                                        "growth_rate": [r["growth_rate"] for r in lv]}
    gaps = []
    for rpm in SPEEDS:
        for m, against, what in (("lebb", "ffrf", "linear beam vs small-strain solid"),
                                 ("gcms", "ffrf", "same theory, absolute coordinates"),
                                 ("nebb", "tlf", "von Karman beam vs nonlinear solid"),
                                 ("ancf", "tlf", "ANCF continuum beam vs nonlinear solid"),
                                 ("tlf", "ffrf", "nonlinear vs small-strain solid")):
            a, b = refs.get(f"{m}@{rpm:g}"), refs.get(f"{against}@{rpm:g}")
            if a and b:
                ta, tb = np.array(a["tip_m"]), np.array(b["tip_m"])
                gaps.append({"rpm": rpm, "method": m, "against": against, "what": what,
                             "components_pct": (100 * (ta / tb - 1)).tolist(),
                             "norm_pct": 100 * relative_error(ta, tb)})
    diag = {}
    d = {r["case"]: r for r in data["diagnosis"]}
    nebb_ref, tlf_ref = refs.get(f"nebb@{SPEEDS[0]:g}"), refs.get(f"tlf@{SPEEDS[0]:g}")
    if nebb_ref and tlf_ref and d:
        small = [r for r in data["diagnosis"] if r["load_scale"] != 1.0]
        full_gap = 100 * (np.array(nebb_ref["tip_m"]) / np.array(tlf_ref["tip_m"]) - 1)
        diag = {"earlier": [{"method": r["method"], "case": r["case"], "tip_m": r["tip_m"],
                             "error_vs_own_reference": _error(refs, r)}
                            for r in data["diagnosis"] if r["load_scale"] == 1.0],
                "gap_full_load_pct": full_gap.tolist()}
        if len(small) == 2:
            a = next(r for r in small if r["method"] == "nebb")
            b = next(r for r in small if r["method"] == "tlf")
            diag["gap_small_load_pct"] = (100 * (np.array(a["tip_m"]) / np.array(b["tip_m"])
                                                 - 1)).tolist()
            diag["small_load_scale"] = small[0]["load_scale"]
    return {"references": refs, "gaps": gaps, "diagnosis": diag}


def _error(refs: dict, row: dict) -> float | None:
    """A diagnosis row's error against its method's reference at its speed (None without)."""
    ref = refs.get(f"{row['method']}@{row['rpm']:g}")
    return None if ref is None else relative_error(row["tip_m"], ref["tip_m"])


def _mm(v, spec="+.4f"):
    return " / ".join(format(1e3 * x, spec) for x in v)


def _pct(v, spec="+.2f"):
    return " / ".join("-" if x is None else format(x, spec) for x in v)


def render(data: dict, res: dict, scene: Scene) -> str:
    info = data["info"]
    g = scene.geometry
    lines = ["# Six methods on a NACA airfoil blade (fxflex bench airfoil)", "",
             f"Blade: NACA {g.airfoil}, length {g.length:g} m, chord {g.root_y:g} -> "
             f"{g.tip_y:g} m, twist {g.twist_deg:g} deg, line load {scene.load.line_load:g} N/m, "
             f"c = {scene.damping.c:g}, {scene.damping.model} damping; beams "
             f"`{scene.mesh.beam_variant}`. Machine: {info['machine'].get('cpu', '?')}, "
             f"{info['ranks']} rank(s), load {info['load_start']:.1f} at the start"
             + (f", {info['load_end']:.1f} at the end; {info['wall_s']:.0f} s wall"
                if "wall_s" in info else "") + ("; **--quick** (coarse levels, not the "
                                               "reported figures)" if info["quick"] else "") + ".",
             "", "## Each method against its own converged reference", "",
             "Steady tip deflection (longitudinal / orthogonal / load, mm) at three levels "
             "(solids: Q2 levels m; beams: elements), Richardson's reference and the observed "
             "order per component, the finest level's error against the reference, and the "
             "stability verdict at each level (max Re lambda, 1/s).", ""]
    body = []
    for key, ref in res["references"].items():
        lv = _by(data["rows"], ref["method"], ref["rpm"])
        for r, e in zip(lv, ref["errors"]):
            body.append([ref["method"], f"{ref['rpm']:g}", r["n"], r["dof"], _mm(r["tip_m"]),
                         f"{e:.2e}", str(r["stable"]),
                         "-" if r["growth_rate"] is None else f"{r['growth_rate']:+.4g}"])
        body.append([ref["method"], f"{ref['rpm']:g}", "ref", "", _mm(ref["tip_m"]),
                     "order " + _pct(ref["order"], ".2f"), "", ""])
    lines += [markdown_table(["method", "rpm", "level", "dof", "tip mm", "error / order",
                              "stable", "max Re lambda"], body), ""]
    lines += ["## The six side by side", ""]
    for rpm in SPEEDS:
        rows = [[r["method"], _mm(r["tip_m"]), _pct(r["order"], ".2f"), f"{r['estimate']:.1e}",
                 "stable" if all(s is True for s in r["stable"]) else
                 "unstable" if all(s is False for s in r["stable"]) else
                 "levels disagree: " + ", ".join(map(str, r["stable"])),
                 "-" if r["growth_rate"][-1] is None else f"{r['growth_rate'][-1]:+.4g}"]
                for r in res["references"].values() if r["rpm"] == rpm]
        lines += [f"### {rpm:g} rpm", "",
                  markdown_table(["method", "reference tip mm", "observed order",
                                  "finest vs reference", "verdict (all levels)",
                                  "max Re lambda (finest)"], rows), ""]
    lines += ["## Model gaps between the converged references", "",
              markdown_table(["rpm", "method", "against", "theories", "per component %",
                              "|difference| / |reference| %"],
                             [[f"{x['rpm']:g}", x["method"], x["against"], x["what"],
                               _pct(x["components_pct"]), f"{x['norm_pct']:.2f}"]
                              for x in res["gaps"]]), ""]
    d = res["diagnosis"]
    if d:
        lines += ["## Diagnosis: TLF -0.125 m against NEBB -0.108 m (1000 rpm)", "",
                  markdown_table(["method", "case", "tip mm", "error vs its own reference"],
                                 [[x["method"], x["case"], _mm(x["tip_m"]),
                                   "-" if x["error_vs_own_reference"] is None else
                                   f"{100 * x['error_vs_own_reference']:.2f} %"]
                                  for x in d["earlier"]]), "",
                  "Converged NEBB against converged TLF (per component, %): full load "
                  + _pct(d["gap_full_load_pct"]) + (
                      f"; load x {d['small_load_scale']:g} (NEBB on the finest beam level, TLF "
                      "on solid level 2): " + _pct(d["gap_small_load_pct"])
                      if "gap_small_load_pct" in d else "") + ".", ""]
    return "\n".join(lines) + "\n"


def run(scene: Scene, out_dir: str, comm, quick: bool = False) -> dict:
    """Both studies (module docstring); the JSON is written as the rows come."""
    base = blade(scene)
    info = {"machine": machine(), "load_start": os.getloadavg()[0], "ranks": comm.size,
            "quick": quick, "scene": base.to_dict()}
    store = _Store(os.path.join(out_dir, "airfoil.json") if out_dir else "", comm, info)

    def log(text):
        _log(comm, text)

    t0 = time.perf_counter()
    log(f"bench airfoil: NACA {base.geometry.airfoil}, {len(METHODS)} methods x "
        f"{len(SPEEDS)} speeds x 3 levels")
    _levels_study(store, base, comm, METHODS, quick, log)
    log("diagnosis (1000 rpm)")
    _diagnosis(store, base, comm, quick, log)
    info.update(load_end=os.getloadavg()[0], wall_s=time.perf_counter() - t0)
    res = assemble(store.data)
    store.data["results"] = res
    store.save()
    text = render(store.data, res, base)
    if comm.rank == 0 and out_dir:
        with open(os.path.join(out_dir, "airfoil.md"), "w") as fh:
            fh.write(text)
    verdicts = {k: r["stable"][-1] for k, r in res["references"].items()}
    summary = [f"bench airfoil: {len(store.data['rows'])} steady states in "
               f"{info['wall_s']:.0f} s"] + [
        f"  {r['method']:5s} {r['rpm']:6g} rpm  reference {_mm(r['tip_m'])} mm  order "
        f"{_pct(r['order'], '.2f')}  stable {verdicts[k]}" for k, r in res["references"].items()]
    return {"summary": "\n".join(summary) + f"\n(tables in {out_dir}/airfoil.md)",
            "info": info, "results": res, "scene": base}
