"""``fxflex bench skip``: what each skip and each cache saves (issue 7, part 5).

1. Caches, cold against warm, each in fresh ``fxflex`` processes on a private cache folder
   (``<out>/cache``, emptied first): the solid mesh (``steady --method tlf``), the clamped
   eigenmodes and the FFRF/GCMS projections (``steady --method ffrf|gcms`` with
   ``FXFLEX_NO_CACHE`` barring the kinds not under test), the TLF invariant matrices
   (``run --method tlf --force-eval invariant``, a few steps).
2. Skips, in this process, best of ``repeats``: the time loop of ``fxflex run`` with no output
   asked for (before: the tip and the extra outputs -- drive torque -- sampled at the default
   interval of a 10 ms run; now: nothing sampled) and at 0 rpm (before: rotation terms evaluated,
   measured at 1e-6 rpm, which takes the general path -- not 1e-300 rpm, whose products
   underflow into subnormal numbers that slow the arithmetic; now: dropped); the element route's
   build without the system invariant matrices; what ``steady`` does not build (TLF transient
   operators) and what ``run`` does not compute (TLF steady state, CD limit w_max by SLEPc,
   computed only to diagnose a divergence).
3. ``fxflex compare`` before (no eigenmode, projection or invariant cache; mesh cached, as before
   this work) and after, cold (empty cache) and warm (second run).

Tables go to ``skip.md``, data to ``skip.json``. Timings on a shared machine are noisy: the
load average is recorded next to every figure.
"""

from __future__ import annotations

import json
import os
import shutil
import time

from fxflex.bench.common import machine, markdown_table, run_cli
from fxflex.formulation import PAPER_INTEGRATION, BuildOptions, build
from fxflex.io.payload import jsonable
from fxflex.scene import METHODS, Scene
from fxflex.time import simulate

__all__ = ["run", "cache_rows", "loop_rows", "build_rows", "compare_rows"]

#: the t_end of ``fxflex run`` by default, which set the old sampling interval
_T_END = 0.01


def _load() -> float:
    return round(os.getloadavg()[0], 2)


def _child(args, scene, folder, no_cache=""):
    """``fxflex ARGS --json`` on the private cache ``folder``; FXFLEX_NO_CACHE = ``no_cache``."""
    load = _load()
    out = run_cli(args, scene, env={"FXFLEX_CACHE": folder, "FXFLEX_NO_CACHE": no_cache or "0"})
    if "error" in out:
        raise RuntimeError(f"fxflex {' '.join(args)}: {out['error']}")
    out["load_average"] = load
    return out


def _pair(what, command, cold, warm, part=None) -> dict:
    """A cache row: preprocessing (or ``part`` of it) and process wall time, cold and warm."""
    def pick(r):
        return r["detail_timings_s"].get(part, 0.0) if part else r["timings_s"]["preprocess"]
    return {"what": what, "command": command, "cold_s": pick(cold), "warm_s": pick(warm),
            "saving_s": pick(cold) - pick(warm), "cold_wall_s": cold["wall_s"],
            "warm_wall_s": warm["wall_s"], "load_average": [cold["load_average"],
                                                            warm["load_average"]],
            "detail_cold": cold["detail_timings_s"], "detail_warm": warm["detail_timings_s"]}


def cache_rows(scene: Scene, folder: str, say) -> list[dict]:
    """Cold and warm runs of each cache, on the empty private cache ``folder``."""
    shutil.rmtree(folder, ignore_errors=True)
    rows = []
    say("bench skip: mesh cache")
    steady = ["steady", "--method", "tlf"]
    cold = _child(steady, scene, folder)
    rows.append(_pair("mesh (.msh)", "steady --method tlf", cold, _child(steady, scene, folder),
                      part="mesh"))
    rows[-1]["tlf_steady_solve_s"] = cold["timings_s"]["solve"]
    for method in ("ffrf", "gcms"):
        say(f"bench skip: {method} eigenmodes and projections")
        args = ["steady", "--method", method]
        nothing = _child(args, scene, folder, "modes,reduced")
        _child(args, scene, folder, "reduced")                # writes the modes (if not there)
        modes = _child(args, scene, folder, "reduced")
        _child(args, scene, folder)                           # writes the projections
        both = _child(args, scene, folder)
        command = f"steady --method {method}"
        rows += [_pair(f"{method}: eigenmodes", command, nothing, modes),
                 _pair(f"{method}: projections (with the modes cached)", command, modes, both),
                 _pair(f"{method}: eigenmodes + projections", command, nothing, both)]
    say("bench skip: TLF invariant matrices")
    dt = PAPER_INTEGRATION["tlf"][1]
    args = ["run", "--method", "tlf", "--force-eval", "invariant", "--t-end", repr(10 * dt)]
    cold = _child(args, scene, folder, "tlf-invariants")
    _child(args, scene, folder)                               # writes them
    rows.append(_pair("tlf: invariant matrices", "run --method tlf --force-eval invariant",
                      cold, _child(args, scene, folder)))
    return rows


def _best(fn, repeats: int) -> float:
    return min(fn() for _ in range(repeats))


def _per_step(form, method, steps, sample_every, on_sample=None) -> float:
    """CPU microseconds per step (process time: a shared machine's waits do not count)."""
    integrator, dt = PAPER_INTEGRATION[method]
    cpu = time.process_time()
    res = simulate(form, integrator, dt, steps * dt, sample_every=sample_every,
                   on_sample=on_sample)
    return 1e6 * (time.process_time() - cpu) / res.steps


def _interleaved(runs: dict, repeats: int) -> dict:
    """Best of ``repeats`` of each callable, taken in turns so that load changes hit all alike."""
    best = {k: float("inf") for k in runs}
    for _ in range(repeats):
        for k, fn in runs.items():
            best[k] = min(best[k], fn())
    return best


def loop_rows(scene: Scene, comm, steps: dict, repeats: int, say) -> list[dict]:
    """CPU us per step of each method: run without output (before/now) and 0 rpm (before/now)."""
    rows = []
    for method in METHODS:
        say(f"bench skip: {method} time loop")
        n = steps[method]
        dt = PAPER_INTEGRATION[method][1]
        old_every = max(1, int(round(max(dt, _T_END / 20000) / dt)))
        options = BuildOptions(need_steady=False)
        form = build(method, scene, comm, options)
        rest = build(method, scene.replace(**{"rotation.rpm": 0.0}), comm, options)
        general = build(method, scene.replace(**{"rotation.rpm": 1e-6}), comm, options)
        load = _load()
        t = _interleaved({
            "sampled": lambda: _per_step(form, method, n, old_every, lambda *a: None),
            "silent": lambda: _per_step(form, method, n, n),
            "general": lambda: _per_step(general, method, n, n),
            "rest": lambda: _per_step(rest, method, n, n)}, repeats)
        rows.append({"method": method, "steps": n, "old_sample_every": old_every,
                     "sampled_us": t["sampled"], "silent_us": t["silent"],
                     "output_saving": 1.0 - t["silent"] / t["sampled"],
                     "rest_general_us": t["general"], "rest_us": t["rest"],
                     "rest_saving": 1.0 - t["rest"] / t["general"],
                     "load_average": [load, _load()]})
    return rows


def build_rows(scene: Scene, comm, repeats: int) -> list[dict]:
    """Build work skipped: the element route's system matrices, TLF's transient operators in
    ``steady`` and its w_max in ``run`` (computed only to diagnose a divergence)."""
    from fxflex.solid.tlf import largest_frequency

    rows = []
    for method in ("nebb", "ancf"):
        def element():
            t0 = time.perf_counter()
            form = build(method, scene, comm, BuildOptions(force_eval="element"))
            return time.perf_counter() - t0, form
        now = _best(lambda: element()[0], repeats)
        _, form = element()

        def system(form=form):
            t0 = time.perf_counter()
            form.engine._build_system()
            return time.perf_counter() - t0
        rows.append({"what": f"{method} --force-eval element: system invariant matrices not built",
                     "now_s": now, "skipped_s": _best(system, repeats),
                     "load_average": _load()})
    tlf = build("tlf", scene, comm, BuildOptions(need_steady=False))
    rows.append({"what": "tlf steady: transient operators (UFL force, lumped mass) not built",
                 "now_s": tlf.timings["build"],
                 "skipped_s": tlf.timings["force_build"] + tlf.timings["mass_build"],
                 "load_average": _load()})
    t0 = time.perf_counter()
    largest_frequency(tlf.model, "lumped")
    rows.append({"what": "tlf run: CD limit w_max (SLEPc) only on divergence",
                 "now_s": 0.0, "skipped_s": time.perf_counter() - t0, "load_average": _load()})
    return rows


def compare_rows(scene: Scene, folder: str, out_dir: str, methods, say) -> list[dict]:
    """``fxflex compare`` before (mesh cached only) and after, cold and warm."""
    fresh = folder + "-compare"
    shutil.rmtree(fresh, ignore_errors=True)
    os.makedirs(fresh)
    if os.path.isdir(os.path.join(folder, "meshes")):
        shutil.copytree(os.path.join(folder, "meshes"), os.path.join(fresh, "meshes"))
    runs = (("before: mesh cached only", folder, "modes,reduced,tlf-invariants"),
            ("after: cold cache (mesh cached)", fresh, ""), ("after: warm cache", fresh, ""))
    rows = []
    for label, where, bar in runs:
        say(f"bench skip: compare, {label}")
        out = _child(["compare", "--methods", ",".join(methods), "--out",
                      os.path.join(out_dir, "compare")], scene, where, bar)
        per = {}
        for r in out["steady"]:
            per[r["method"]] = per.get(r["method"], 0.0) + r["seconds"]
        rows.append({"run": label, "seconds": out["seconds"], "wall_s": out["wall_s"],
                     "per_method_s": per, "load_average": out["load_average"]})
    return rows


def render(d: dict) -> str:
    lines = ["# What skipping saves (issue 7, part 5)", "",
             f"{'QUICK smoke run; ' if d['quick'] else ''}mesh {d['mesh']}, machine "
             f"{d['machine']['cpu']} ({d['machine']['cores']} cores), {d['machine']['date']}, "
             f"load average {d['load_average_start']} at the start (shared machine: noisy).", "",
             "## Caches: cold against warm (separate processes, private cache folder)", "",
             "Preprocessing as reported by the command (`timings_s.preprocess`; the mesh row: "
             "its mesh part), and the whole process.", ""]
    lines.append(markdown_table(
        ["what", "command", "cold s", "warm s", "saved s", "process cold / warm s", "load"],
        [[r["what"], f"`{r['command']}`", r["cold_s"], r["warm_s"], r["saving_s"],
          f"{r['cold_wall_s']:.2f} / {r['warm_wall_s']:.2f}", r["load_average"]]
         for r in d["caches"]]))
    lines += ["## The time loop: what `fxflex run` no longer computes (CPU us per step, best "
              f"of {d['repeats']}, interleaved)", "",
              "Without `--out`/`--fields` nothing is sampled (before: the tip and the drive "
              "torque at the default interval of a 10 ms run, every `old every` steps). At 0 rpm "
              "the rotation terms are dropped (before: evaluated; measured at 1e-6 rpm, which "
              "takes the general path).", ""]
    lines.append(markdown_table(
        ["method", "steps", "old every", "sampled", "no output", "saved", "0 rpm general",
         "0 rpm skipped", "saved", "load"],
        [[r["method"], r["steps"], r["old_sample_every"], r["sampled_us"], r["silent_us"],
          f"{100 * r['output_saving']:.0f} %", r["rest_general_us"], r["rest_us"],
          f"{100 * r['rest_saving']:.0f} %", r["load_average"]] for r in d["loops"]]))
    lines += ["## Build work not done", ""]
    lines.append(markdown_table(["what", "build now s", "not done s", "load"],
                                [[r["what"], r["now_s"], r["skipped_s"], r["load_average"]]
                                 for r in d["builds"]]))
    tlf_solve = next((r.get("tlf_steady_solve_s") for r in d["caches"]
                      if "tlf_steady_solve_s" in r), None)
    if tlf_solve is not None:
        lines += [f"`fxflex run` does not solve the steady state: {tlf_solve:.2f} s for TLF "
                  "(Newton, `steady --method tlf`); the beams and reduced models solve theirs "
                  "only to diagnose a divergence.", ""]
    lines += [f"## `fxflex compare --methods {','.join(d['compare_methods'])}`", ""]
    lines.append(markdown_table(
        ["run", "total s", "process s"] + [f"{m} s" for m in d["compare_methods"]] + ["load"],
        [[r["run"], r["seconds"], r["wall_s"]] + [r["per_method_s"].get(m, 0.0)
                                                  for m in d["compare_methods"]]
         + [r["load_average"]] for r in d["compare"]]))
    return "\n".join(lines) + "\n"


def run(scene: Scene, out_dir: str, comm, quick: bool = False) -> dict:
    """Every measurement above on ``scene`` (``quick``: a 20x4x2 mesh, few steps, FFRF, GCMS,
    TLF and LEBB in the compare)."""
    if comm.size > 1:
        from fxflex.errors import FxflexError
        raise FxflexError("bench skip: runs serially (it starts its own fxflex processes)")
    if quick:
        scene = scene.replace(**{"mesh.solid": (20, 4, 2)})

    def say(text):
        print(text, flush=True, file=__import__("sys").stderr)

    load0 = _load()
    folder = os.path.join(out_dir, "cache")
    repeats = 2 if quick else 5
    steps = {m: (200 if quick else 10000) for m in METHODS}
    steps["tlf"] = 20 if quick else 200
    steps["ancf"] = 200 if quick else 2000
    methods = ["ffrf", "gcms", "tlf", "lebb"] if quick else list(METHODS)
    data = {"quick": quick, "mesh": list(scene.mesh.solid), "machine": machine(),
            "load_average_start": load0, "repeats": repeats,
            "caches": cache_rows(scene, folder, say),
            "loops": loop_rows(scene, comm, steps, repeats, say),
            "builds": build_rows(scene, comm, repeats),
            "compare": compare_rows(scene, folder, out_dir, methods, say),
            "compare_methods": methods}
    data = jsonable(data)
    text = render(data)
    with open(os.path.join(out_dir, "skip.md"), "w") as fh:
        fh.write(text)
    with open(os.path.join(out_dir, "skip.json"), "w") as fh:
        json.dump(data, fh, indent=1)
    cmp_ = {r["run"]: r["seconds"] for r in data["compare"]}
    both = [r for r in data["caches"] if r["what"].endswith("eigenmodes + projections")]
    data["summary"] = (
        "bench skip: " + "; ".join(f"{r['what'].split(':')[0]} preprocessing {r['cold_s']:.2f} -> "
                                   f"{r['warm_s']:.2f} s" for r in both)
        + f"; compare {' -> '.join(f'{v:.1f}' for v in cmp_.values())} s "
          f"(before / cold / warm); tables in {os.path.join(out_dir, 'skip.md')}")
    return data
