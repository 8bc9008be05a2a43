"""``fxflex bench paper``: the paper's efficiency tables (Sect. 4.2) on this machine.

- **Table 3**: preprocessing (the build from nothing but the mesh, read from its cache:
  assembly, eigenmodes, projections, invariant matrices, mass; the other caches bypassed) and 1e4 AB2 steps at dt = 0.02 us for all six methods at 1000 rpm,
  c3, with their DOF counts (each method's default force evaluation; TLF with its default
  lumped mass).
- **Table 4**: TLF-CD with (``invariant``) and without (``ufl``, the per-step integration of
  Eq. 65) system invariant matrices at three mesh sizes, time per step extrapolated to 1e4 steps
  (:func:`fxflex.bench.tlf_speed.table4`).
- **Tables 5 and 6**: NEBB-AB and ANCF-CD with system invariant matrices against the element
  route (Eq. 66; element invariant matrices) at 10 and 20 elements, 1e4 steps at dt = 0.02 us
  (:func:`fxflex.bench.beams.tables_5_6`).

One Markdown table each in ``paper.md``, the data in ``paper.json``. Run it on one process; the
machine's load average is recorded next to the figures (they are wall times).
"""

from __future__ import annotations

import json
import os
import sys

from fxflex import cache
from fxflex.bench.beams import tables_5_6, time_steps
from fxflex.bench.common import machine, markdown_table
from fxflex.bench.tlf_speed import table4
from fxflex.formulation import PAPER_AB_STEP
from fxflex.scene import METHODS, Scene

__all__ = ["run", "table3"]


def table3(scene: Scene, comm, steps: int, say=print) -> list[dict]:
    """Preprocessing and ``steps`` AB2 steps at the paper's 0.02 us for every method; the
    preprocessing builds everything (eigenmodes, projections, invariant matrices), reading only
    the mesh from the cache, as ``bench reduced`` and ``bench tlf`` do."""
    rows = []
    for m in METHODS:
        with cache.bypass("modes", "reduced", "tlf-invariants"):
            rows.append(time_steps(scene, m, None, "ab2", PAPER_AB_STEP, steps, comm=comm))
        say(f"bench paper: table 3 {m}: preprocess {rows[-1]['preprocess_s']:.2f} s, "
            f"{steps} steps {rows[-1]['solve_s']:.2f} s")
    return rows


def _md(meta: dict, t3, t4, t56, steps: int, t4_steps: int) -> str:
    lines = ["# The paper's efficiency tables (Sect. 4.2) on this machine", "",
             f"{meta['machine']['cpu']}, {meta['machine']['cores']} cores, "
             f"{meta['machine']['date']}; {meta['ranks']} rank(s); load average "
             f"{meta['load_start']:.2f} at the start, {meta['load_end']:.2f} at the end (the "
             f"machine may be shared: these are wall times). 1000 rpm, c3.", "",
             f"## Table 3: preprocessing and {steps:g} AB2 steps at dt = 0.02 us", "",
             markdown_table(["method", "dof", "force eval", "preprocess (s)",
                             f"{steps:g} AB steps (s)", "us/step"],
                            [[r["method"].upper() + "-AB", r["dof"], r["force_eval"] or "-",
                              f"{r['preprocess_s']:.2f}", f"{r['solve_s']:.2f}",
                              f"{r['us_per_step']:.1f}"] for r in t3]),
             "TLF uses its default lumped mass and UFL force; FFRF and GCMS count their modal "
             "coordinates (GCMS after the Gram cut).", "",
             "## Table 4: TLF-CD with and without system invariant matrices", "",
             markdown_table(["mesh", "dof", "system invariant matrices", "preprocess (s)",
                             "1e4 steps (s)", "ms/step"],
                            [[" x ".join(map(str, r["mesh"])), r["dof"],
                              "yes" if r["force_eval"] == "invariant" else "no (UFL, Eq. 65)",
                              f"{r['preprocess_s']:.2f}", f"{r['solve_1e4_s']:.1f}",
                              f"{r['ms_per_step']:.2f}"] for r in t4]),
             f"1e4 steps extrapolated from {t4_steps} CD steps (lumped mass); the time per step "
             "does not depend on dt.", "",
             f"## Table 5: NEBB-AB with and without system invariant matrices ({steps:g} steps, "
             "dt = 0.02 us)", "",
             markdown_table(["elements", "dof", "system invariant matrices", "preprocess (s)",
                             f"{steps:g} steps (s)", "CPU (s)"],
                            [[r["n_el"], r["dof"], "yes" if r["force_eval"] == "invariant" else
                              "no (Eq. 66)", f"{r['preprocess_s']:.3f}", f"{r['solve_s']:.3f}",
                              f"{r['cpu_s']:.3f}"] for r in t56 if r["method"] == "nebb"]),
             f"## Table 6: ANCF-CD, system against element invariant matrices ({steps:g} steps, "
             "dt = 0.02 us)", "",
             markdown_table(["elements", "dof", "invariant matrices", "preprocess (s)",
                             f"{steps:g} steps (s)", "CPU (s)"],
                            [[r["n_el"], r["dof"], "system" if r["force_eval"] == "invariant"
                              else "element", f"{r['preprocess_s']:.3f}", f"{r['solve_s']:.3f}",
                              f"{r['cpu_s']:.3f}"] for r in t56 if r["method"] == "ancf"])]
    ratios = []
    for name, rows, key, base in (("TLF-CD", t4, "ms_per_step", "ufl"),
                                  ("NEBB-AB", [r for r in t56 if r["method"] == "nebb"],
                                   "solve_s", "element"),
                                  ("ANCF-CD", [r for r in t56 if r["method"] == "ancf"],
                                   "solve_s", "element")):
        by = {}
        for r in rows:
            by.setdefault(tuple(r["mesh"]) if "mesh" in r else r["n_el"], {})[r["force_eval"]] = r
        for size, pair in by.items():
            if "invariant" in pair and base in pair:
                ratios.append(f"{name} {size}: {pair[base][key] / pair['invariant'][key]:.2f}x")
    lines += ["", "Speed-up of the system invariant matrices (time without / with): "
              + "; ".join(ratios) + ". The paper finds at least 10x for TLF-CD and ANCF-CD and a "
              "slight gain for NEBB-AB (SPEC section 7)."]
    return "\n".join(lines) + "\n"


def run(scene: Scene, out_dir: str, comm, quick: bool = False) -> dict:
    def say(text):
        if comm.rank == 0:
            print(text, file=sys.stderr, flush=True)

    load0 = os.getloadavg()[0]
    base = scene.replace(**{"rotation.rpm": 1000.0, "damping.c": 1000.0,
                            "damping.model": "relative", "rotation.profile": "constant"})
    if quick:
        base = base.replace(**{"mesh.solid": (10, 2, 2), "mesh.beam_elements": 4})
    steps = 200 if quick else 10_000
    t3 = table3(base, comm, steps, say)
    divisions = [(10, 2, 2), (20, 4, 2)] if quick else [(50, 6, 4), (100, 12, 6), (150, 18, 8)]
    t4_steps = 20 if quick else 200
    say("bench paper: table 4 (TLF-CD, invariant matrices on/off)")
    t4 = table4(base, comm, divisions, t4_steps)
    say("bench paper: tables 5 and 6 (NEBB-AB, ANCF-CD)")
    t56 = tables_5_6(base, (4, 8) if quick else (10, 20), steps)
    meta = {"machine": machine(), "ranks": comm.size, "load_start": load0,
            "load_end": os.getloadavg()[0], "quick": quick}
    text = _md(meta, t3, t4, t56, steps, t4_steps)
    data = {"meta": meta, "table3": t3, "table4": t4, "tables_5_6": t56}
    if comm.rank == 0:
        with open(os.path.join(out_dir, "paper.md"), "w") as fh:
            fh.write(text)
        with open(os.path.join(out_dir, "paper.json"), "w") as fh:
            json.dump(data, fh, indent=1, default=float)
    return {"summary": text, **data}
