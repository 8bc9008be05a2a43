"""``fxflex bench beams``: LEBB, NEBB and ANCF -- speed, accuracy checks, the paper's comparisons.

Tables (Markdown, written to the output folder as ``beams.md``, data as ``beams.json``):

1. preprocessing and 1e4 steps on the default scene with the paper's integrator and step, for
   each force evaluation (targets: LEBB and NEBB-AB2 under 1 s, ANCF-CD under 3 s);
2. the paper's Table 5 (NEBB-AB) and Table 6 (ANCF-CD), invariant vs element force evaluation
   at two element counts, step 0.02 us as in the paper's efficiency study (Sect. 4.2);
3. closed-form checks: uniform cantilever (q L^4 / 8 E I) and spinning bar (rho Omega^2 L^3 / 3 E),
   both ANCF root clamps;
4. steady deflections at 1000, 5000, 10000 rpm with 10, 20, 40 elements and the stability verdict
   (an eigenvalue of the linearised rotating system with positive real part);
5. the paper's ratios at 1000 rpm (LEBB vs FFRF, NEBB vs TLF, ANCF vs TLF), the solid steady
   states computed here when their modules are available.

Every rank computes (the beam models are replicated); rank 0 writes. ``quick`` shrinks meshes
and step counts for a smoke run.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

from fxflex.formulation import BuildOptions, PAPER_AB_STEP, PAPER_INTEGRATION, build
from fxflex.scene import Scene
from fxflex.time import simulate

__all__ = ["run", "time_steps", "tables_5_6", "steady_table", "closed_form_checks",
           "PAPER_RATIOS"]

#: Sect. 4.1 at 1000 rpm, c3: (beam, solid, allowed relative difference per component %)
PAPER_RATIOS = (("lebb", "ffrf", (1.5, 1.5, 1.5)), ("nebb", "tlf", (1.3, 1.3, 1.3)),
                ("ancf", "tlf", (1.7, 4.0, 1.5)))
COMPONENTS = ("longitudinal", "orthogonal", "load")
UNIFORM = {"geometry.tip_y": 0.12, "geometry.tip_z": 0.06, "geometry.twist_deg": 0.0}


def time_steps(scene: Scene, method: str, force_eval: str | None, integrator: str, dt: float,
               steps: int, comm=None) -> dict:
    """Preprocessing (build) and wall time of ``steps`` steps (the tip checked every 100 steps).
    ``comm`` is needed by the solid methods only (the beams are replicated)."""
    t0 = time.perf_counter()
    form = build(method, scene, comm, BuildOptions(force_eval=force_eval, need_steady=False))
    pre = time.perf_counter() - t0
    cpu0 = time.process_time()
    res = simulate(form, integrator, dt, steps * dt, sample_every=steps)
    cpu = time.process_time() - cpu0
    return {"method": method, "force_eval": form.force_eval,
            "integrator": integrator, "dt_s": dt,
            "n_el": scene.mesh.beam_elements, "dof": form.dof, "preprocess_s": pre,
            "steps": res.steps, "solve_s": res.wall_s, "cpu_s": cpu, "us_per_step": 1e6 * res.wall_s / res.steps,
            "diverged": res.diverged is not None}


def tables_5_6(scene: Scene, counts, steps: int) -> list[dict]:
    """The paper's Tables 5 (NEBB-AB) and 6 (ANCF-CD): invariant against element force
    evaluation for each element count, ``steps`` steps at dt = 0.02 us (Sect. 4.2)."""
    return [time_steps(scene.replace(**{"mesh.beam_elements": n}), m, fe, integ, PAPER_AB_STEP,
                       steps)
            for m, integ in (("nebb", "ab2"), ("ancf", "cd"))
            for n in counts for fe in ("invariant", "element")]


def _steady(scene: Scene, method: str) -> dict:
    form = build(method, scene, None)
    st = form.steady_state()
    rate, freq = form.growth_rate()
    return {"method": method, "rpm": scene.rotation.rpm, "n_el": scene.mesh.beam_elements,
            "tip_mm": (1e3 * np.asarray(st.tip)).tolist(), "converged": st.converged,
            "iterations": st.iterations, "growth_rate": rate, "stable": rate <= 0.0}


def steady_table(scene: Scene, rpms, counts) -> list[dict]:
    return [_steady(scene.replace(**{"rotation.rpm": float(r), "mesh.beam_elements": n}), m)
            for m in ("lebb", "nebb", "ancf") for r in rpms for n in counts]


def closed_form_checks(scene: Scene) -> list[dict]:
    """Uniform untwisted beam: cantilever at rest (q = -800 N/m) and spinning bar (1000 rpm)."""
    base = scene.replace(**UNIFORM, **{"geometry.hub_radius": 0.0})
    E, rho = base.material.E, base.material.rho
    Iy = base.geometry.root_y * base.geometry.root_z**3 / 12
    cases = {"cantilever": (base.replace(**{"rotation.rpm": 0.0, "load.line_load": -800.0}), 2,
                            -800.0 * base.geometry.length**4 / (8 * E * Iy)),
             "spinning bar": (base.replace(**{"rotation.rpm": 1000.0, "load.line_load": 0.0}), 0,
                              rho * (1000.0 * np.pi / 30) ** 2 * base.geometry.length**3 / (3 * E))}
    rows = []
    for name, (sc, k, ref) in cases.items():
        for m, root in (("lebb", None), ("nebb", None), ("ancf", "free-axial"), ("ancf", "full")):
            s = sc if root is None else sc.replace(**{"mesh.ancf_root": root})
            tip = build(m, s, None).steady_state().tip[k]
            rows.append({"case": name, "method": m + (f" ({root})" if root else ""),
                         "value_mm": 1e3 * tip, "reference_mm": 1e3 * ref,
                         "error_pct": 100 * (tip / ref - 1)})
    return rows


def _solid_steady(scene: Scene, comm) -> dict:
    out = {}
    for m in ("ffrf", "tlf"):
        try:
            form = build(m, scene, comm)
        except Exception as exc:                      # noqa: BLE001 - report, do not fail
            out[m] = {"error": f"{type(exc).__name__}: {exc}"}
            continue
        out[m] = {"tip_mm": (1e3 * np.asarray(form.steady_state().tip)).tolist()}
    return out


def _md(rows: list[list], head: list[str]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def run(scene: Scene, out_dir: str, comm, quick: bool = False) -> dict:
    steps = 1000 if quick else 10000
    counts = (4, 8) if quick else (10, 20, 40)
    eff_counts = (4, 8) if quick else (10, 20)
    default = scene.replace(**{"rotation.rpm": 1000.0})
    speed = []
    for m, fe in (("lebb", None), ("nebb", "invariant"), ("nebb", "element"),
                  ("ancf", "invariant"), ("ancf", "element")):
        integ, dt = PAPER_INTEGRATION[m]
        speed.append(time_steps(default, m, fe, integ, dt, steps))
    tables56 = tables_5_6(default, eff_counts, steps)
    checks = closed_form_checks(scene)
    steady = steady_table(scene, (1000.0, 5000.0, 10000.0), counts)
    solids = {} if quick else _solid_steady(default, comm)
    ratios = []
    for beam, solid, allowed in PAPER_RATIOS:
        if solid not in solids or "tip_mm" not in solids[solid]:
            continue
        b = next(r for r in steady if r["method"] == beam and r["rpm"] == 1000.0
                 and r["n_el"] == counts[0])["tip_mm"]
        s = solids[solid]["tip_mm"]
        diff = [100 * (bi / si - 1) for bi, si in zip(b, s)]
        ratios.append({"pair": f"{beam} vs {solid}", "diff_pct": diff, "paper_pct": allowed,
                       "met": [abs(d) <= a for d, a in zip(diff, allowed)]})

    md = ["# Beam formulations: benchmark", "",
          f"{'quick smoke run; ' if quick else ''}{os.cpu_count()} cores, load average "
          f"{os.getloadavg()[0]:.2f} at the start; "
          f"1 step = one explicit step with the paper's integrator; tip sampled every 100 steps.",
          "", f"## Speed on the default scene ({steps} steps, paper's step)", "",
          _md([[r["method"], r["force_eval"] or "-", r["integrator"], f"{r['dt_s']:.2g}",
                r["dof"], f"{r['preprocess_s']:.3f}", f"{r['solve_s']:.3f}",
                f"{r['cpu_s']:.3f}", f"{r['us_per_step']:.1f}"] for r in speed],
              ["method", "force eval", "integrator", "dt (s)", "dof", "preprocess (s)",
               f"{steps} steps (s)", "CPU (s)", "us/step"]),
          "", f"## Paper Tables 5 and 6: invariant vs element ({steps} steps, dt = 0.02 us)", "",
          _md([[r["method"], r["integrator"], r["n_el"], r["dof"], r["force_eval"],
                f"{r['preprocess_s']:.3f}", f"{r['solve_s']:.3f}", f"{r['cpu_s']:.3f}"]
               for r in tables56],
              ["method", "integrator", "elements", "dof", "force eval", "preprocess (s)",
               f"{steps} steps (s)", "CPU (s)"]),
          "", "## Closed-form checks (uniform untwisted beam, 10 elements)", "",
          _md([[r["case"], r["method"], f"{r['value_mm']:.6g}", f"{r['reference_mm']:.6g}",
                f"{r['error_pct']:+.3f}"] for r in checks],
              ["case", "method", "tip (mm)", "closed form (mm)", "error (%)"]),
          "", "## Steady deflections (mm) and stability", "",
          _md([[r["method"], f"{r['rpm']:g}", r["n_el"]] + [f"{v:+.5f}" for v in r["tip_mm"]]
               + [f"{r['growth_rate']:+.4g}", "stable" if r["stable"] else "UNSTABLE"]
               for r in steady],
              ["method", "rpm", "elements", "longitudinal", "orthogonal", "load",
               "max Re(lambda) (1/s)", "verdict"])]
    if solids:
        md += ["", "## Comparison with the solid methods at 1000 rpm "
               f"({counts[0]} beam elements)", "",
               _md([[m] + ([f"{v:+.5f}" for v in d["tip_mm"]] if "tip_mm" in d else
                           [d["error"], "", ""]) for m, d in solids.items()],
                   ["solid", "longitudinal", "orthogonal", "load"]), "",
               _md([[r["pair"]] + [f"{d:+.2f} ({'met' if ok else 'NOT met'}, paper {a})"
                                   for d, ok, a in zip(r["diff_pct"], r["met"], r["paper_pct"])]
                    for r in ratios], ["pair", *COMPONENTS])]
    result = {"speed": speed, "tables_5_6": tables56, "closed_form": checks, "steady": steady,
              "solids": solids, "ratios": ratios}
    if comm.rank == 0:
        with open(os.path.join(out_dir, "beams.md"), "w") as fh:
            fh.write("\n".join(md) + "\n")
        with open(os.path.join(out_dir, "beams.json"), "w") as fh:
            json.dump(result, fh, indent=1, default=float)
    lines = [f"bench beams: {os.path.join(out_dir, 'beams.md')}"]
    lines += [f"  {r['method']:4s} {r['force_eval'] or '':9s} {r['integrator']} {steps} steps "
              f"{r['solve_s']:.2f} s wall, {r['cpu_s']:.2f} s CPU (preprocess "
              f"{r['preprocess_s']:.2f} s)" for r in speed]
    lines += [f"  {r['pair']}: " + ", ".join(f"{c} {d:+.2f} %" for c, d in
                                              zip(COMPONENTS, r["diff_pct"])) for r in ratios]
    result["summary"] = "\n".join(lines)
    return result
