"""The ``fxflex`` command line (SPEC section 8).

Every command takes ``--scene FILE.toml``, ``--set KEY=VALUE`` (repeatable) and ``--json``.
With ``--json`` stdout carries one JSON object and nothing else; progress and logs go to stderr.
Bad input ends with one line on stderr naming what is wrong and what is allowed, exit status 2,
and nothing written: output paths are checked before anything is built (:mod:`fxflex.io.paths`).
An output that fails while the command runs, or an unexpected error, is one line too, exit
status 1; an interrupt exits 130 (a run first flushes its series and reports what it did).
Under MPI every rank runs the command; only rank 0 prints and writes. An error every rank meets
together is printed once by rank 0; a rank that fails alone prints its line and aborts the job
(:func:`_fail`), so that no rank waits forever in a collective for it.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import sys
import time
import traceback
from dataclasses import dataclass

from fxflex import __version__
from fxflex.cache import KINDS as CACHE_KINDS
from fxflex.errors import FxflexError, OutputError
from fxflex.io.paths import Output, check_paths
from fxflex.scene import METHODS, load_scene

__all__ = ["main"]

log = logging.getLogger("fxflex")

#: seconds the ranks that fail wait for the others before one aborts the job alone
AGREE_S = 5.0
#: exit statuses: bad input, output or run failure, interrupt
EXIT_INPUT, EXIT_FAILURE, EXIT_INTERRUPT = 2, 1, 130


BENCHES = ("steady", "tlf", "reduced", "beams", "paper", "accuracy", "stability", "skip",
           "implicit", "convergence", "tol", "airfoil", "pybmodes")


class _Parser(argparse.ArgumentParser):
    """argparse whose errors are one line: ``fxflex: error: <what> ; allowed: ...``."""

    def error(self, message):
        raise FxflexError(message)


def _number(name, positive: bool = False):
    """argparse type: a finite float (> 0 when ``positive``); argparse prefixes the option name."""
    def check(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
        if positive and not value > 0:
            raise argparse.ArgumentTypeError(f"must be > 0, got {text!r}")
        return value
    return check


def _positive(name):
    return _number(name, positive=True)


def _count(minimum: int):
    """argparse type: an integer >= minimum."""
    def check(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {text!r}")
        return value
    return check


def _method(text):
    if text not in METHODS:
        raise argparse.ArgumentTypeError(f"{text!r} is not a method; allowed: {' '.join(METHODS)}")
    return text


def _method_list(text):
    methods = [m.strip() for m in text.split(",") if m.strip()]
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise argparse.ArgumentTypeError(f"{','.join(bad) or text!r} not a method; allowed: "
                                         f"{','.join(METHODS)}")
    return methods


def _common(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("scene")
    g.add_argument("--scene", metavar="FILE.toml", help="scene file (SPEC section 8)")
    g.add_argument("--set", metavar="KEY=VALUE", action="append", default=[], dest="overrides",
                   help="override a scene key, e.g. --set geometry.twist_deg=0 (repeatable)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")


def _physics(p: argparse.ArgumentParser) -> None:
    p.add_argument("--rpm", type=_number("--rpm"), help="hub speed (rev/min); sets rotation.rpm")
    p.add_argument("--damping", type=_number("--damping"), metavar="C",
                   help="damping coefficient c (kg s^-1 m^-3); sets damping.c")
    p.add_argument("--damping-model", choices=("relative", "absolute"),
                   help="sets damping.model (SPEC section 5)")


def _tolerance(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--tol", type=_positive("--tol"), metavar="EPS",
                   help=f"refine the discretisation until the estimated error ({what}) is "
                        "below EPS (docs/tolerance.md)")
    p.add_argument("--tol-levels", type=_count(2), metavar="N",
                   help="with --tol: at most N meshes of the refinement ladder (default: the "
                        "whole ladder)")


def make_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="fxflex", description=__doc__.split("\n\n")[0],
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"fxflex {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    p = sub.add_parser("info", help="the resolved scene and each method's DOF count")
    p.add_argument("--method", type=_method, help="only this method")
    _common(p)

    p = sub.add_parser("steady", help="rotating-frame equilibrium at constant speed")
    p.add_argument("--method", type=_method, required=True, help=" | ".join(METHODS))
    _physics(p)
    _tolerance(p, "each tip component relative to |tip|")
    _common(p)

    p = sub.add_parser("run", help="transient simulation; tip deflection history")
    p.add_argument("--method", type=_method, required=True, help=" | ".join(METHODS))
    _physics(p)
    p.add_argument("--t-end", type=_positive("--t-end"), default=0.01, metavar="T",
                   help="end time (s), default 0.01")
    p.add_argument("--dt", type=_positive("--dt"), metavar="DT",
                   help="time step (s); default: the paper's step for ab2/cd; for "
                        "generalized-alpha 20e-6 (tlf 10e-6) up to 1000 rpm, scaled by "
                        "(1000/rpm)^1.5 above, not below 4e-6 (docs/implicit.md)")
    p.add_argument("--integrator", choices=("ab2", "cd", "generalized-alpha"),
                   help="default: the paper's (ab2 for ffrf gcms lebb nebb, cd for tlf ancf)")
    p.add_argument("--rho-inf", type=_number("--rho-inf"), metavar="X",
                   help="generalized-alpha: spectral radius at infinity in [0, 1] (1: no "
                        "numerical damping), default 0.9")
    p.add_argument("--force-eval", choices=("ufl", "invariant", "element"),
                   help="internal force route: tlf ufl|invariant, nebb/ancf invariant|element")
    p.add_argument("--mass", choices=("consistent", "lumped"), help="tlf mass matrix")
    p.add_argument("--out", metavar="FILE.csv",
                   help="write the time series as it goes (without --out and --fields nothing "
                        "is sampled: only the final deflection is reported)")
    p.add_argument("--fields", metavar="FILE.xdmf",
                   help="write the fields every --fields-every samples, every method (XDMF "
                        "for ParaView: u, U_hub; beams: on the centerline, with the section "
                        "rotation)")
    p.add_argument("--fields-every", type=int, default=100, metavar="N",
                   help="samples between field snapshots, default 100")
    p.add_argument("--sample-dt", type=_positive("--sample-dt"), metavar="DT",
                   help="output interval (s); default max(dt, t_end/20000)")
    p.add_argument("--checkpoint", metavar="FILE",
                   help="write a checkpoint (.npz, atomically replaced) every "
                        "--checkpoint-every steps")
    p.add_argument("--checkpoint-every", type=int, metavar="N",
                   help="steps between checkpoints; default 5 %% of the run (with --checkpoint) "
                        "or the resumed run's; without --checkpoint it writes FILE.csv.ckpt")
    p.add_argument("--resume", metavar="CHECKPOINT",
                   help="continue the run a checkpoint belongs to (same scene and run options): "
                        "the series is cut back to the checkpoint and appended")
    _tolerance(p, "the tip history's time-integration error relative to its peak, by "
                  "adaptive generalized-alpha steps; the mesh as steady --tol chooses it unless "
                  "the scene sets it")
    _common(p)

    p = sub.add_parser("modes", help="modes and stability of the motion about the rotating "
                                     "steady state; Campbell diagram")
    p.add_argument("--method", type=_method, required=True, help=" | ".join(METHODS))
    _physics(p)
    p.add_argument("--n", type=int, default=10, metavar="N",
                   help="number of modes (conjugate pairs), lowest frequency first; default 10")
    p.add_argument("--campbell", metavar="RPM_MIN:RPM_MAX:COUNT",
                   help="modes at COUNT speeds from RPM_MIN to RPM_MAX: Campbell diagram (PNG) "
                        "with the 1x, 2x rotation lines and unstable ranges shaded, CSV, JSON")
    p.add_argument("--mass", choices=("consistent", "lumped"),
                   help="tlf mass matrix (default: as for run)")
    p.add_argument("--out", metavar="DIR",
                   help="output folder: with --campbell the diagram's PNG, CSVs and JSON "
                        "(default out/modes); without it, only if given, modes_<method>.json "
                        "and the mode shapes shapes_<method>.csv and shapes_<method>.png")
    p.add_argument("--elastodyn", metavar="FILE",
                   help="write the mode-shape section of an ElastoDyn blade file (BldFl1Sh, "
                        "BldFl2Sh, BldEdgSh: x^2..x^6 polynomials fitted to flap 1, flap 2 and "
                        "edge 1 at the scene's speed; at least 6 modes are computed, more until "
                        "those are found); not with --campbell")
    _tolerance(p, "each frequency relative to itself")
    _common(p)

    p = sub.add_parser("compare", help="the paper's comparison: every method at the three "
                                       "paper speeds, next to the paper's figures")
    p.add_argument("--methods", type=_method_list, default=list(METHODS), metavar="M,...",
                   help="comma-separated subset of " + ",".join(METHODS))
    p.add_argument("--out", metavar="DIR", default="out/compare",
                   help="output folder (default out/compare)")
    p.add_argument("--full", action="store_true",
                   help="the paper's windows for every method, TLF included (about 50 min; "
                        "the time estimate is printed after the equilibria, before the runs)")
    _common(p)

    p = sub.add_parser("cache", help="what fxflex keeps on disk between runs (meshes, eigenmodes, "
                                     "invariant matrices): list it or clear it",
                       description="The cache folder is $FXFLEX_CACHE (default ~/.cache/fxflex). "
                                   "FXFLEX_NO_CACHE=1 makes every command bypass it "
                                   "(FXFLEX_NO_CACHE=modes,reduced: only those kinds). Entries "
                                   "are keyed by everything they depend on, so clearing is only "
                                   "needed to free disk space (docs/performance.md).")
    p.add_argument("action", choices=("info", "clear"), metavar="ACTION", help="info | clear")
    p.add_argument("--kind", choices=tuple(CACHE_KINDS), metavar="KIND",
                   help="only this kind: " + " | ".join(CACHE_KINDS))
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")

    p = sub.add_parser("section", help="cross-section properties along the span (2-D finite-"
                                       "element analysis; SPEC section 9)")
    p.add_argument("--stations", type=_count(1), metavar="N",
                   help="N evenly spaced stations (default: the stations table's rows, or 11)")
    p.add_argument("--resolution", type=_count(4), metavar="M",
                   help="section mesh: M elements across the larger extent (default 40)")
    p.add_argument("--plot", metavar="DIR",
                   help="write section_NN.png (mesh, centroid, shear centre, principal axes) and "
                        "blade.png into DIR")
    _common(p)

    p = sub.add_parser("bench", help="benchmarks; tables written to --out")
    p.add_argument("name", choices=BENCHES, metavar="NAME", help=" | ".join(BENCHES))
    p.add_argument("--out", metavar="DIR", default="out/bench",
                   help="output folder (default out/bench)")
    p.add_argument("--quick", action="store_true",
                   help="smaller meshes and fewer repeats (a smoke run, not the reported figures)")
    p.add_argument("--reference", action="store_true",
                   help="accuracy only: recompute the converged reference (refined Q1 and Q2 "
                        "meshes, Richardson extrapolation; about 25 minutes) and store it, "
                        "instead of the work-precision study")
    _common(p)
    return parser


def _scene_from_args(args):
    overrides = list(args.overrides)
    for flag, key in (("rpm", "rotation.rpm"), ("damping", "damping.c"),
                      ("damping_model", "damping.model")):
        value = getattr(args, flag, None)
        if value is not None:
            overrides.append(f"{key}={json.dumps(value)}")
    return load_scene(args.scene, overrides)


def _emit(comm, args, payload: dict, text: str) -> None:
    if comm.rank != 0:
        return
    if args.json:
        sys.stdout.write(json.dumps(payload) + "\n")
    else:
        sys.stdout.write(text.rstrip("\n") + "\n")
    sys.stdout.flush()


def _fmt_tip(tip_mm: dict) -> str:
    return "  ".join(f"{k} {v:+.6f} mm" if v is not None else f"{k} nan"
                     for k, v in tip_mm.items())


def cmd_info(args, comm) -> None:
    from fxflex.formulation import dof_count, method_info
    from fxflex.io import envelope

    scene = _scene_from_args(args)
    methods = [args.method] if args.method else list(METHODS)
    # the methods that do not take other sections yet refuse them (docs/sections.md)
    dofs = {m: dof_count(m, scene) if _takes(m, scene) else None for m in methods}
    payload = envelope(scene, methods={m: {"description": method_info()[m], "dof": dofs[m]}
                                       for m in methods})
    lines = [f"fxflex {__version__}   scene {scene.hash}"]
    for sec, table in scene.to_dict().items():
        lines.append(f"[{sec}]")
        lines += [f"  {k} = {json.dumps(v)}" for k, v in table.items()]
    lines.append("methods:")
    for m in methods:
        d = dofs[m]
        note = "" if d is not None else ("  (dof known after preprocessing)"
                                         if _takes(m, scene) else
                                         "  (refuses this section: see fxflex steady)")
        lines.append(f"  {m:5s} dof {d if d is not None else '-':>7}   {method_info()[m]}{note}")
    lines += ["discretisation (README, docs/accuracy.md, docs/beams.md):",
              "  mesh.solid_degree = 1 (the paper's Q1, 1.6-1.7 % stiff on the default blade) | 2 "
              "(27-node Q2: 0.2 % on [24,2,2])",
              "  mesh.beam_variant = \"paper\" (Eq. 45-57) | \"locking-free\" (NEBB, ANCF on "
              "slender blades)",
              "  which for 1 %, 0.1 %: docs/accuracy.md; measured by fxflex bench convergence"]
    _emit(comm, args, payload, "\n".join(lines))


def _takes(method: str, scene) -> bool:
    """Whether ``method`` runs on the scene's section (fxflex.scene.load.validate_for)."""
    from fxflex.errors import SceneError
    from fxflex.scene.load import validate_for

    if scene.geometry.paper_shape:
        return True
    try:
        validate_for(method, scene)
    except SceneError:
        return False
    return True


def _warn(comm, warnings: list[str], *notes: str | None) -> None:
    """Gather a command's warnings: each note that is not None (the formulation's warnings, the
    stability verdict's reason, a step note) joins ``warnings``, the payload's list, and is
    logged from rank 0 (the notes are the same on every rank). ``steady`` and ``run`` use it."""
    for note in notes:
        if note:
            warnings.append(note)
            if comm.rank == 0:
                log.warning(note)


def cmd_steady(args, comm) -> None:
    from fxflex.analysis.tolerance import json_fields, steady_to_tolerance
    from fxflex.formulation import build
    from fxflex.numerics.qep import verdict as stability_verdict
    from fxflex.io import envelope, tip_mm

    scene = _scene_from_args(args)
    if scene.rotation.profile != "constant":
        log.warning("steady: rotation.profile = %r; solving at the final speed %g rpm",
                    scene.rotation.profile, scene.rotation.rpm)
    t0 = time.perf_counter()
    refined, failed = _refined(args, comm, lambda **kw: steady_to_tolerance(
        args.method, scene, comm, args.tol, **kw), scene)
    if refined is None:
        form = build(args.method, scene, comm)
        t1 = time.perf_counter()
        st = form.steady_state()
        timings = {"preprocess": t1 - t0, "solve": time.perf_counter() - t1}
    else:                           # the finest level: its build and solve, then the whole ladder
        best, scene = refined["best"], refined["scene"]
        form, st = best["form"], best["steady"]
        timings = {"preprocess": best["build_s"], "solve": best["seconds"] - best["build_s"],
                   "refinement": time.perf_counter() - t0}
    verdict, why = stability_verdict(form, st)
    warnings: list[str] = []
    _warn(comm, warnings, *form.warnings, why)
    payload = envelope(scene, method=args.method, rpm=scene.rotation.rpm, dof=form.dof,
                       tip_mm=tip_mm(st.tip), stable=verdict, converged=st.converged,
                       iterations=st.iterations, warnings=warnings, timings_s=timings,
                       detail_timings_s={**form.timings, **st.timings}, **st.extra,
                       **json_fields(refined, "steady"))
    text = (f"{args.method} steady state at {scene.rotation.rpm:g} rpm  (dof {form.dof}, "
            f"{st.iterations} iterations, {'converged' if st.converged else 'NOT converged'})\n"
            f"  tip: {_fmt_tip(tip_mm(st.tip))}\n"
            f"  stable: {verdict}   preprocess {timings['preprocess']:.2f} s, "
            f"solve {timings['solve']:.2f} s"
            + _tol_text(refined)
            + "".join(f"\n  WARNING: {note}" for note in warnings))
    _emit(comm, args, payload, text)
    if failed is not None:
        raise failed
    if not st.converged:
        raise SystemExit(1)


def _refined(args, comm, refine, scene):
    """``--tol``: (the refinement, None) or, when a cap stops it above EPS, (its best, the
    error to raise after the best result is written); without --tol (None, None)."""
    from fxflex.analysis.tolerance import ToleranceNotMet

    if args.tol is None:
        if args.tol_levels is not None:
            raise FxflexError("--tol-levels: only with --tol EPS")
        return None, None

    try:
        return refine(max_levels=args.tol_levels), None
    except ToleranceNotMet as exc:
        return exc.result, exc


def _tol_text(refined) -> str:
    from fxflex.analysis.tolerance import shown

    if refined is None:
        return ""
    return (f"\n  --tol: {len(refined['levels'])} levels, reached "
            f"{shown(refined['discretisation'])}, estimated "
            f"error {max(refined['estimate']):.3g} ({', '.join(sorted(set(refined['how'])))})")


@dataclass
class _RunPlan:
    """What ``run`` settles from its arguments before anything is built: the integration, the
    sampling, the output paths and, with --resume, the checkpoint read back."""

    integrator: str
    dt: float
    nsteps: int
    rho_inf: float | None
    sample_every: int
    #: what a checkpoint records and a resume must match (fxflex.io.checkpoint.check_settings)
    settings: dict
    out_path: str | None
    ckpt_path: str | None
    ckpt_every: int | None
    #: the checkpoint's metadata and arrays (rank 0), its series record, with --resume
    resumed: dict | None
    arrays: dict | None
    series: dict | None
    warnings: list[str]
    #: --tol: EPS, the sample interval and the checkpoint interval in time (variable steps)
    tol: float | None = None
    sample_dt: float | None = None
    ckpt_dt: float | None = None


def _run_integration(args, scene, comm, warnings: list[str]
                     ) -> tuple[str, float, int, float | None]:
    """(integrator, dt, steps, rho_inf): the paper's integration unless given, the step shortened
    to end exactly at --t-end (a warning says so), rho_inf for generalized-alpha only."""
    from fxflex.time.driver import plan_integration

    plan = plan_integration(args.method, args.integrator, args.dt, args.t_end, args.rho_inf,
                            scene.rotation.rpm)
    _warn(comm, warnings, plan.note)
    return plan.integrator, plan.dt, plan.steps, plan.rho_inf


def _plan_run(args, scene, comm) -> _RunPlan:
    """Check every argument of ``run`` and resolve the outputs, before anything is built: the
    integration, --resume (the checkpoint read back and its settings matched), the sampling,
    the checkpoint path and interval, and every output path (:func:`_check_run_paths`)."""
    from fxflex.io.checkpoint import check_settings, load_checkpoint
    from fxflex.time.driver import sample_steps

    warnings: list[str] = []
    if args.tol is None:
        if args.tol_levels is not None:
            raise FxflexError("--tol-levels: only with --tol EPS")
        integrator, dt, nsteps, rho_inf = _run_integration(args, scene, comm, warnings)
    else:
        integrator, dt, nsteps, rho_inf = _tol_integration(args, scene)
    adaptive = args.tol is not None and integrator == "generalized-alpha"
    if args.fields_every < 1:
        raise FxflexError(f"--fields-every: must be >= 1, got {args.fields_every}")
    if args.checkpoint_every is not None and args.checkpoint_every < 1:
        raise FxflexError(f"--checkpoint-every: must be >= 1 step, got {args.checkpoint_every}")
    out_path, ckpt_path, ckpt_every = args.out, args.checkpoint, args.checkpoint_every
    resumed = arrays = series = None
    if args.resume is not None:
        if args.fields:
            raise FxflexError("--fields: cannot be combined with --resume (an XDMF series "
                              "cannot be continued); write the fields in a run of its own")
        resumed, arrays = load_checkpoint(args.resume, comm)
        series = resumed.get("series")
        if series is None and args.out:
            raise FxflexError("--out: the checkpointed run wrote no series; resume without --out")
        out_path = args.out if args.out is not None else (series["path"] if series else None)
    sample_every = sample_steps(dt, args.t_end, args.sample_dt)
    sample_dt = ckpt_dt = None
    if adaptive:                    # rows at the asked times, interpolated (fxflex.time.adaptive)
        from fxflex.formulation import implicit_step
        sample_dt = args.sample_dt or implicit_step(args.method, scene.rotation.rpm)
        sample_every = None
    if not (out_path or args.fields):
        sample_every = nsteps       # nothing to write: only the final deflection is reported
        sample_dt = args.t_end if adaptive else None
    settings = {"method": args.method, "integrator": integrator, "dt_s": dt,
                "t_end_s": args.t_end, "t0_s": 0.0, "sample_every": sample_every,
                "rho_inf": rho_inf, "tol": args.tol}
    if adaptive:
        settings["sample_dt_s"] = sample_dt
    if resumed is not None:
        if args.tol is None:        # with --tol the scene is checked once the mesh is chosen
            check_settings(resumed, scene.to_dict(), scene.hash, settings, args.resume)
        ckpt_path = ckpt_path or resumed["checkpoint"]["path"]
        ckpt_every = ckpt_every or resumed["checkpoint"]["every"]
        ckpt_dt = resumed["checkpoint"].get("every_s") if ckpt_every is None else None
    if ckpt_every is not None and ckpt_path is None:
        if not out_path:
            raise FxflexError("--checkpoint-every: needs --checkpoint FILE (or --out FILE.csv, "
                              "whose name + .ckpt is then used)")
        ckpt_path = out_path + ".ckpt"
    if ckpt_path is not None and ckpt_every is None and ckpt_dt is None:
        if adaptive:
            ckpt_dt = args.t_end / 20             # every 5 % of the run, in time
        else:
            ckpt_every = max(nsteps // 20, 1)     # every 5 % of the run
    plan = _RunPlan(integrator, dt, nsteps, rho_inf, sample_every, settings, out_path, ckpt_path,
                    ckpt_every, resumed, arrays, series, warnings, args.tol, sample_dt, ckpt_dt)
    _check_run_paths(args, comm, plan)
    return plan


def _tol_integration(args, scene) -> tuple[str, float, int, float | None]:
    """``run --tol``: (integrator, first step, a provisional step count, rho_inf).
    generalized-alpha (the default with --tol) starts at --dt, or a tenth of its default fixed
    step, and then chooses its steps; ab2 and cd take their step from the model after the build
    (:func:`_tol_explicit`), so --dt is refused with them."""
    from fxflex.formulation import implicit_step
    from fxflex.time.driver import plan_integration

    if not 0.0 < args.tol < 1.0:
        raise FxflexError(f"--tol: got {args.tol:g}; allowed: 0 < EPS < 1 (a relative error)")
    integrator = args.integrator or "generalized-alpha"
    if integrator != "generalized-alpha" and args.dt is not None:
        raise FxflexError(f"--dt: not with --tol and --integrator {integrator} (the step is the "
                          "largest stable one with a margin, docs/tolerance.md); leave out --dt, "
                          "or use generalized-alpha, where --dt is the first step")
    plan = plan_integration(args.method, integrator, None, args.t_end, args.rho_inf,
                            scene.rotation.rpm)
    dt = plan.dt
    if integrator == "generalized-alpha":
        dt = args.dt if args.dt is not None else implicit_step(args.method,
                                                               scene.rotation.rpm) / 10
    return integrator, dt, max(int(round(args.t_end / dt)), 1), plan.rho_inf


def _given_keys(args) -> set[str]:
    """Dotted scene keys the user set (the --scene file's and --set's; --rpm and --damping
    set no discretisation key)."""
    import tomllib

    from fxflex.scene.load import parse_override

    tables = [parse_override(text) for text in args.overrides]
    if args.scene:
        with open(args.scene, "rb") as fh:          # load_scene has read and checked it
            tables.append(tomllib.load(fh))
    return {f"{sec}.{key}" for table in tables for sec, values in table.items()
            if isinstance(values, dict) for key in values}


def _tol_space(args, comm, scene, options):
    """``run --tol``: (scene, form, refinement, failure, fixed keys): the discretisation as
    ``steady --tol`` chooses it (and its form, built once), unless the scene sets one of the
    method's discretisation keys (fxflex.analysis.tolerance.DISCRETISATION_KEYS), which is then
    kept as it is."""
    from dataclasses import replace

    from fxflex.analysis.tolerance import Refiner, fixing_keys, steady_to_tolerance
    from fxflex.formulation import build

    fixed = fixing_keys(args.method, _given_keys(args))
    if fixed:
        if args.tol_levels is not None:
            raise FxflexError(f"--tol-levels: the scene fixes the discretisation "
                              f"({', '.join(fixed)}): nothing to refine")
        return scene, build(args.method, scene, comm, options), None, None, fixed
    refiner = Refiner(args.method, comm, replace(options, need_steady=True))
    refined, failed = _refined(args, comm, lambda **kw: steady_to_tolerance(
        args.method, scene, comm, args.tol, refiner=refiner, **kw), scene)
    return refined["scene"], refined["best"]["form"], refined, failed, fixed


def _tol_explicit(args, comm, plan: _RunPlan, form) -> str:
    """``run --tol`` with ab2 or cd: the plan's step from the model's top frequency
    (:func:`fxflex.time.adaptive.explicit_step`), shortened to end at --t-end; the rule."""
    from fxflex.time.adaptive import explicit_step
    from fxflex.time.driver import sample_steps, step_to_end
    from fxflex.time.step_stability import top_mode

    w, d = top_mode(form)
    h, rule = explicit_step(plan.integrator, w, d, args.t_end, args.tol)
    plan.dt, plan.nsteps = step_to_end(args.t_end, h)
    plan.sample_every = (sample_steps(plan.dt, args.t_end, args.sample_dt)
                         if (plan.out_path or args.fields) else plan.nsteps)
    if plan.ckpt_path and not args.checkpoint_every and plan.resumed is None:
        plan.ckpt_every = max(plan.nsteps // 20, 1)
    plan.settings.update(dt_s=plan.dt, sample_every=plan.sample_every)
    return rule


def _check_run_paths(args, comm, plan: _RunPlan) -> None:
    """Every output of ``run`` writable and no input overwritten (:mod:`fxflex.io.paths`); on a
    resume, the series on disk begins with the bytes the checkpoint recorded. Collective."""
    from fxflex.io.series import prefix_digest

    fields_h5 = (os.path.splitext(args.fields)[0] + ".h5",) if args.fields else ()
    check_paths(comm, [Output("--out", plan.out_path),
                       Output("--fields", args.fields, suffix=".xdmf", beside=fields_h5),
                       Output("--checkpoint", plan.ckpt_path)],
                inputs={"--scene": args.scene, "--resume": args.resume},
                may_replace=(("--checkpoint", "--resume"),))
    series, out_path = plan.series, plan.out_path
    if series is not None:
        ok = None
        if comm.rank == 0:
            ok = (os.path.isfile(out_path)
                  and prefix_digest(out_path, series["bytes"]) == series["sha256"])
        if not comm.bcast(ok, root=0):
            raise FxflexError(f"--resume: {out_path} does not begin with the {series['bytes']} "
                              "bytes the checkpoint recorded (a different or shortened file); "
                              "pass the run's series with --out")


def _restart(comm, plan: _RunPlan, form):
    """(layout, state, resume): the checkpoint's distributed layout when one is written or read,
    and with --resume the state (q, v) and the integrator's history scattered to this
    partition. Collective."""
    from fxflex.io.checkpoint import Layout
    from fxflex.time import Resume

    resumed, arrays = plan.resumed, plan.arrays
    layout = Layout(form) if (plan.ckpt_path or resumed) else None
    state = resume = None
    if resumed is not None:
        state = (layout.scatter(arrays["q"] if comm.rank == 0 else None),
                 layout.scatter(arrays["v"] if comm.rank == 0 else None))
        names = comm.bcast([k[7:] for k in arrays if k.startswith("scheme/")]
                           if comm.rank == 0 else None, root=0)
        history = {n: layout.scatter(arrays[f"scheme/{n}"] if comm.rank == 0 else None)
                   for n in names}
        resume = Resume(step=resumed["step"], arrays=history, samples=resumed["samples"])
    return layout, state, resume


def _open_outputs(args, comm, scene, plan: _RunPlan, form, layout, implicit: dict):
    """(fields, series writer, checkpoint writer), each None when not asked for: the XDMF
    fields of the formulation, the CSV series (rank 0 writes; continued on a resume) and the
    checkpoint file."""
    from fxflex.io import SeriesWriter, envelope
    from fxflex.io.checkpoint import FORMAT, CheckpointWriter

    fields = None
    if args.fields:
        if form.field_writer is None:
            raise FxflexError(f"--fields: not available for {args.method}")
        fields = form.field_writer(args.fields)
    columns = ["t_s", "longitudinal_m", "orthogonal_m", "load_m"] + list(form.extra_columns)
    settings, series = plan.settings, plan.series
    meta = envelope(scene, method=args.method, integrator=plan.integrator, dt_s=plan.dt,
                    **implicit, t_end_s=args.t_end, dof=form.dof,
                    force_eval=settings["force_eval"], mass=settings["mass"])
    writer = None
    if plan.out_path:
        writer = _agreed(comm, SeriesWriter, plan.out_path, meta, columns,
                         enabled=comm.rank == 0,
                         resume=(series["bytes"], series["sha256"]) if series else None)
    checkpoint = None
    if plan.ckpt_path:
        resumed = plan.resumed
        checkpoint = CheckpointWriter(
            plan.ckpt_path, layout, {"format": FORMAT, "fxflex_version": __version__,
                                     "scene": scene.to_dict(), "scene_hash": scene.hash,
                                     "settings": settings, "layout": layout.kind,
                                     "ranks": comm.size, "dof": form.dof, "series": None,
                                     "checkpoint": {"path": os.path.abspath(plan.ckpt_path),
                                                    "every": plan.ckpt_every,
                                                    "every_s": plan.ckpt_dt}},
            series=writer,
            last=(os.path.abspath(args.resume), resumed["step"]) if resumed else None)
    return fields, writer, checkpoint


def _simulate_with_outputs(args, comm, form, plan: _RunPlan, state, resume, fields, writer,
                           checkpoint, scale: float | None = None):
    """The run itself, samples going to the series and every --fields-every-th to the fields.
    Both are closed when it ends; when it fails, an output failure leaves no half-written series
    and anything else keeps what was computed, flushed."""
    from fxflex.io import Progress
    from fxflex.time import simulate

    adaptive = plan.sample_dt is not None
    progress = Progress(1000 if adaptive else plan.nsteps,
                        f"{args.method} {plan.integrator} "
                        + (f"--tol {plan.tol:g}" if adaptive else f"dt={plan.dt:.3g}"),
                        enabled=comm.rank == 0)

    count = [0]

    def on_sample(t, tip, extras, q=None):
        if writer is not None:
            _agreed(comm, writer.write, (t, *tip, *extras))
        if fields is not None and count[0] % args.fields_every == 0:
            fields.write(t, q)
        count[0] += 1

    try:
        if adaptive:
            from fxflex.time.adaptive import Clock, simulate_adaptive
            clock = Clock.from_dict(plan.resumed["clock"]) if resume else None
            res = simulate_adaptive(
                form, plan.tol, args.t_end, h0=plan.dt, scale=scale or 0.0,
                rho_inf=plan.rho_inf, sample_dt=plan.sample_dt,
                on_sample=on_sample if writer or fields else None, progress=progress,
                extras=writer is not None, state=state, clock=clock,
                arrays=resume.arrays if resume else None,
                checkpoint_every=plan.ckpt_every or 0, checkpoint_dt=plan.ckpt_dt,
                on_checkpoint=checkpoint)
        else:
            res = simulate(form, plan.integrator, plan.dt, args.t_end,
                           sample_every=plan.sample_every,
                           on_sample=on_sample if writer or fields else None,
                           progress=progress, extras=writer is not None, rho_inf=plan.rho_inf,
                           state=state, resume=resume, checkpoint_every=plan.ckpt_every or 0,
                           on_checkpoint=checkpoint)
    except BaseException as exc:
        # Collective clean-up only when every rank is here together.
        if writer is not None:
            writer.close_after(exc)
        if fields is not None and (comm.size == 1 or getattr(exc, "collective", False)):
            fields.close()
        raise
    if writer is not None:
        _agreed(comm, writer.close)
    if fields is not None:
        fields.close()
    progress.close(f"{res.steps} steps" + (" (interrupted)" if res.interrupted else ""))
    return res


def _peak_warning(plan: _RunPlan, res) -> str | None:
    """``run --tol``: the steps are held against max(peak so far, scale) (fxflex/time/adaptive.py),
    so the estimate over the history's own peak can exceed EPS only when that peak stayed below
    the scale (a short run, a slow spin-up): then one line says so."""
    ad = res.adaptive
    if ad is None or res.diverged is not None or res.interrupted:
        return None
    worst = max(ad["error_estimate"])
    if worst <= plan.tol or ad["peak"] >= ad["scale_m"]:
        return None
    return (f"--tol {plan.tol:g}: the tip's peak stayed below the scale the steps were held to "
            f"(the equilibrium's |tip|, {ad['scale_m']:.3g} m): the estimated error is "
            f"{worst:.3g} of the history's peak, above EPS; a longer run or a smaller EPS holds "
            "it")


def _tol_report(args, scene, plan: _RunPlan, res, tol: dict | None) -> tuple[dict, str]:
    """SPEC 9 ``error_estimate`` and ``discretisation`` of ``run`` (both null without --tol)
    and the text line. error_estimate: the time-integration estimate per tip component relative
    to the peak |tip| of the history (adaptive generalized-alpha; null entries for ab2/cd, whose
    step is bounded by stability, not estimated). discretisation: the mesh keys used, the spatial
    estimate of steady --tol (``space_estimate``, relative to |tip| of the equilibrium) or the
    keys that fixed it (``fixed_by``), and the step statistics (``time``)."""
    from fxflex.analysis.tolerance import COMPONENTS, describe, json_fields, shown

    if tol is None:
        return {"error_estimate": None, "discretisation": None}, ""
    refined = tol["refined"]
    space = (json_fields(refined, "steady")["discretisation"] if refined is not None
             else describe(scene, args.method))
    space = dict(space, fixed_by=tol["fixed"] or None,
                 space_estimate=None if refined is None else dict(zip(COMPONENTS,
                                                                      refined["estimate"])))
    ad = res.adaptive
    if ad is not None:
        error = dict(zip(COMPONENTS, ad["error_estimate"]))
        time_info = {"integrator": plan.integrator, "rho_inf": plan.rho_inf, "eps": plan.tol,
                     "steps": ad["accepted"], "rejected": ad["rejected"],
                     "newton_failures": ad["newton_failures"], "dt_first_s": plan.dt,
                     "dt_min_s": ad["h_min"], "dt_max_s": ad["h_max"],
                     "sample_dt_s": plan.sample_dt, "factorizations":
                     res.stats.get("factorizations"),
                     "estimate_kind": "Zienkiewicz-Xie local error per unit step, summed"}
        line = (f"\n  --tol {plan.tol:g}: {ad['accepted']} steps, {ad['rejected']} rejected, dt "
                f"{ad['h_min']:.3g}..{ad['h_max']:.3g} s; estimated time-integration error "
                f"{max(ad['error_estimate']):.3g} of the peak")
    else:
        error = dict.fromkeys(COMPONENTS)
        time_info = {"integrator": plan.integrator, "eps": plan.tol, "steps": res.steps,
                     "rejected": 0, "newton_failures": 0, "dt_s": plan.dt, "rule": tol["rule"],
                     "estimate_kind": "stability-bounded step, not estimated"}
        line = f"\n  --tol {plan.tol:g}: {plan.integrator} at dt {plan.dt:.3g} s ({tol['rule']})"
    line += (f"\n  discretisation: {shown(describe(scene, args.method))}"
             + (f" (fixed by the scene: {', '.join(tol['fixed'])})" if tol["fixed"] else
                f", estimated spatial error {max(refined['estimate']):.3g} (steady --tol)"))
    return {"error_estimate": error, "discretisation": dict(space, time=time_info)}, line


def _run_report(args, scene, form, plan: _RunPlan, res, resume, checkpoint, implicit: dict,
                diverged, verdict, t_pre: float, tol: dict | None = None) -> tuple[dict, str]:
    """(payload, text) of ``run``: the JSON of SPEC section 8 and the human summary."""
    from fxflex.io import envelope, tip_mm

    integrator, dt, out_path, warnings = plan.integrator, plan.dt, plan.out_path, plan.warnings
    first = resume.step if resume else 0
    ckpt_info = None if checkpoint is None else {
        "path": checkpoint.path, "every": plan.ckpt_every, "written": checkpoint.written,
        "seconds": checkpoint.seconds}
    tol_fields, tol_text = _tol_report(args, scene, plan, res, tol)
    payload = envelope(scene, method=args.method, rpm=scene.rotation.rpm, dof=form.dof,
                       integrator=integrator, dt_s=dt, **implicit, t_end_s=args.t_end, t_s=res.t,
                       steps=res.steps, tip_mm=tip_mm(res.tip), stable=verdict,
                       diverged=diverged, interrupted=res.interrupted, warnings=warnings,
                       series=os.path.abspath(out_path) if out_path else None,
                       resumed_from_step=resume.step if resume else None,
                       checkpoint=ckpt_info,
                       timings_s={"preprocess": t_pre, "solve": res.wall_s},
                       detail_timings_s=form.timings, **tol_fields)
    shown_dt = f"dt={dt:.3g} s" if res.adaptive is None else f"--tol {plan.tol:g}"
    text = (f"{args.method} {integrator} {shown_dt}, {res.steps} steps to t={res.t:.6g} s "
            f"(dof {form.dof})\n  tip: {_fmt_tip(tip_mm(res.tip))}\n"
            f"  preprocess {t_pre:.2f} s, solve {res.wall_s:.2f} s"
            + (f" ({1e6 * res.wall_s / (res.steps - first):.1f} us/step)"
               if res.steps > first else ""))
    text += tol_text
    if resume:
        text += f"\n  resumed from step {resume.step} of {args.resume}"
    if plan.rho_inf is not None:
        st = res.stats
        text += (f"\n  generalized-alpha rho_inf {plan.rho_inf:g}: {st['iterations']} Newton "
                 f"iterations, {st['factorizations']} factorisations, {st['halvings']} step "
                 f"halvings")
    if res.interrupted:
        text += f"\n  INTERRUPTED: the deflection above is the last checked, t={res.t:.6g} s"
    if diverged:
        text += (f"\n  STOPPED at t={diverged['time_s']:.6g} s: {diverged['cause']} -- "
                 f"{diverged['detail']}\n  (deflection above: the last finite check, "
                 f"t={res.t:.6g} s)")
    for note in warnings:
        text += f"\n  WARNING: {note}"
    if out_path:
        text += f"\n  series: {out_path}"
    if checkpoint is not None:
        text += f"\n  checkpoints: {checkpoint.written} written to {checkpoint.path}"
    return payload, text


def cmd_run(args, comm) -> None:
    """Plan (every argument checked, outputs resolved), build, restore a checkpoint, open the
    outputs, integrate, diagnose, report (SPEC section 8)."""
    from fxflex.formulation import BuildOptions, build, check_options
    from fxflex.io.checkpoint import check_settings
    from fxflex.numerics.qep import verdict as stability_verdict
    from fxflex.time import diagnose
    from fxflex.time.diagnosis import ab2_warning

    scene = _scene_from_args(args)
    options = BuildOptions(force_eval=args.force_eval, mass=args.mass, need_steady=False)
    check_options(args.method, options)
    plan = _plan_run(args, scene, comm)
    warnings, integrator, dt = plan.warnings, plan.integrator, plan.dt
    t0 = time.perf_counter()
    tol = failed = scale = None
    if plan.tol is None:
        form = build(args.method, scene, comm, options)
    else:
        scene, form, refined, failed, fixed = _tol_space(args, comm, scene, options)
        tol = {"refined": refined, "fixed": fixed, "rule": None}
        if integrator == "generalized-alpha":     # the scale of the step control
            st = refined["best"]["steady"] if refined is not None else form.steady_state()
            scale = math.sqrt(sum(float(x) ** 2 for x in st.tip)) if st.converged else 0.0
        else:
            tol["rule"] = _tol_explicit(args, comm, plan, form)
            dt = plan.dt
    _warn(comm, warnings, *form.warnings)
    t_pre = time.perf_counter() - t0
    plan.settings.update(force_eval=form.force_eval, mass=form.mass_kind)
    if plan.resumed is not None:
        check_settings(plan.resumed, scene.to_dict(), scene.hash, plan.settings, args.resume)
    layout, state, resume = _restart(comm, plan, form)
    implicit = {"rho_inf": plan.rho_inf} if plan.rho_inf is not None else {}
    fields, writer, checkpoint = _open_outputs(args, comm, scene, plan, form, layout, implicit)
    res = _simulate_with_outputs(args, comm, form, plan, state, resume, fields, writer,
                                 checkpoint, scale)
    if res.adaptive is not None:
        dt = res.adaptive["h"]                  # the step the run would take next
    diverged = diagnose(form, integrator, dt, res) if res.diverged else None
    if diverged is None and integrator == "ab2" and not res.interrupted:
        _warn(comm, warnings, ab2_warning(form, dt, res.t))
    if plan.rho_inf is not None:
        implicit["newton"] = res.stats
    verdict, why = (None, None) if res.interrupted else stability_verdict(form)
    _warn(comm, warnings, why)                  # of the equilibrium at the final speed
    _warn(comm, warnings, _peak_warning(plan, res))
    payload, text = _run_report(args, scene, form, plan, res, resume, checkpoint, implicit,
                                diverged, verdict, t_pre, tol)
    _emit(comm, args, payload, text)
    if res.interrupted:
        raise SystemExit(EXIT_INTERRUPT)
    if failed is not None:                      # --tol: the mesh cap ended above EPS
        raise failed


def _agreed(comm, fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` on every rank, where only rank 0 may fail (it writes): an
    OutputError there is raised on every rank, so that none waits in the next collective."""
    error = None
    result = None
    try:
        result = fn(*args, **kwargs)
    except OutputError as exc:
        error = str(exc)
    if comm.size > 1:
        error = comm.bcast(error, root=0)
    if error:
        raise OutputError(error, collective=True)
    return result


def cmd_modes(args, comm) -> None:
    from fxflex.analysis.modes import (ELASTODYN_NOT_CAMPBELL, modes_for_export, run_modes,
                                       single_speed)
    from fxflex.analysis.tolerance import json_fields, modes_to_tolerance
    from fxflex.formulation import BuildOptions, check_options

    scene = _scene_from_args(args)
    options = BuildOptions(mass=args.mass)
    check_options(args.method, options)
    if args.n < 1:
        raise FxflexError(f"--n: must be >= 1, got {args.n}")
    if args.elastodyn is not None and args.campbell:
        raise FxflexError(ELASTODYN_NOT_CAMPBELL)
    out_dir = args.out if args.out is not None else ("out/modes" if args.campbell else None)
    _check_modes_paths(args, comm, out_dir)
    out_dir = os.path.abspath(out_dir) if out_dir is not None else None
    if args.tol is not None and args.campbell:
        raise FxflexError("--tol: not with --campbell (one speed at a time); allowed: --tol "
                          "without --campbell")
    if args.tol is None:
        _refined(args, comm, None, scene)
        payload, text = run_modes(args.method, scene, comm, options, args.n, args.campbell,
                                  out_dir, args.elastodyn)
        payload.update(json_fields(None, "modes"))
        _emit(comm, args, payload, text)
        return
    t0 = time.perf_counter()

    def refine(pairs):
        refined, failed = _refined(args, comm, lambda **kw: modes_to_tolerance(
            args.method, scene, comm, args.tol, pairs, options=options, **kw), scene)
        return refined["best"]["modes"], refined, failed

    modes, refined, failed = modes_for_export(refine, args.n, args.elastodyn is not None)
    best, scene = refined["best"], refined["scene"]
    timings = {"preprocess": best["build_s"], "solve": best["seconds"] - best["build_s"],
               "refinement": time.perf_counter() - t0}
    head = (f"{args.method} modes about the steady state at {scene.rotation.rpm:g} rpm (dof "
            f"{best['dof']})")
    payload, text = single_speed(args.method, scene, comm, modes, best["dof"], timings, out_dir,
                                 args.elastodyn, head=head, tail=_tol_text(refined),
                                 fields=json_fields(refined, "modes"))
    _emit(comm, args, payload, text)
    if failed is not None:
        raise failed


def _check_modes_paths(args, comm, out_dir: str | None) -> None:
    """``modes``' outputs (fxflex.io.paths), and --elastodyn naming a file that --out writes."""
    check_paths(comm, [Output("--out", out_dir, folder=True),
                       Output("--elastodyn", args.elastodyn)], inputs={"--scene": args.scene})
    if args.elastodyn is None or out_dir is None:
        return
    own = {os.path.realpath(os.path.join(out_dir, f"{stem}_{args.method}.{ext}"))
           for stem, ext in (("modes", "json"), ("shapes", "csv"), ("shapes", "png"))}
    if os.path.realpath(args.elastodyn) in own:
        raise FxflexError(f"--elastodyn and --out: both name {args.elastodyn}; allowed: a "
                          "different file for each output")


#: ``fxflex bench NAME`` modules not named NAME (one per name across the package)
BENCH_MODULES = {"tlf": "tlf_speed", "convergence": "refinement", "pybmodes": "peers"}


def cmd_bench(args, comm) -> None:
    """Each benchmark is a module fxflex.bench.<name> (or BENCH_MODULES[name]) with
    ``run(scene, out_dir, comm, quick)`` returning a JSON-able dict and writing its tables
    (Markdown) and data into out_dir; a bench that studies another scene than the user's (bench
    airfoil's NACA blade) returns it as ``scene``, and the envelope reports that one."""
    import importlib

    from fxflex.io import envelope

    scene = _scene_from_args(args)
    options = {}
    if args.reference:
        if args.name != "accuracy":
            raise FxflexError(f"--reference: not an option of bench {args.name}; it applies to "
                              f"accuracy")
        options["reference"] = True
    try:
        name = f"fxflex.bench.{BENCH_MODULES.get(args.name, args.name)}"
        module = importlib.import_module(name)
    except ModuleNotFoundError as exc:
        if exc.name == name:
            raise FxflexError(f"bench: {args.name} is not implemented yet") from None
        raise
    out_dir = os.path.abspath(os.path.join(args.out, args.name))
    check_paths(comm, [Output("--out", out_dir, folder=True)])
    created = _missing_folders(out_dir)
    _agreed(comm, _makedirs, "--out", out_dir, comm.rank == 0)
    try:
        result = module.run(scene, out_dir, comm, quick=args.quick, **options)
    except FxflexError:
        if comm.rank == 0:                # a bench refused before writing: leave nothing
            for folder in created:
                if os.listdir(folder):
                    break
                os.rmdir(folder)
        raise
    payload = envelope(result.pop("scene", scene), bench=args.name, out_dir=out_dir, **result)
    _emit(comm, args, payload, result.get("summary", f"bench {args.name}: see {out_dir}"))


def _missing_folders(path: str) -> list[str]:
    """The folders that creating ``path`` makes, deepest first."""
    out = []
    while path and not os.path.exists(path):
        out.append(path)
        path = os.path.dirname(path)
    return out


def _makedirs(flag: str, path: str, enabled: bool) -> None:
    if not enabled:
        return
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{flag}: cannot create {path}: {exc.strerror or exc}") from None


def cmd_compare(args, comm) -> None:
    from fxflex.analysis.compare import run_compare
    from fxflex.io import envelope

    scene = _scene_from_args(args)
    check_paths(comm, [Output("--out", args.out, folder=True)])
    out_dir = os.path.abspath(args.out)
    if comm.rank == 0:
        sys.stderr.write(f"fxflex compare: {', '.join(args.methods)}"
                         f"{' (--full)' if args.full else ''}; results into {out_dir}\n")

    def progress(text):
        if comm.rank == 0:
            sys.stderr.write(text + "\n")
            sys.stderr.flush()

    result = run_compare(scene, args.methods, out_dir, comm, progress=progress, full=args.full)
    report = result.pop("report")
    payload = envelope(scene, out_dir=out_dir, **result)
    _emit(comm, args, payload, report + f"\n(files in {out_dir})")


def cmd_section(args, comm) -> None:
    """``fxflex section``: the properties of the scene's sections per station; every rank
    computes (a section is small), rank 0 prints and plots."""
    from fxflex.io import envelope
    from fxflex.section.blade import section_table

    scene = _scene_from_args(args)
    if args.plot:
        check_paths(comm, [Output("--plot", args.plot, folder=True)])
    rows = section_table(scene, args.stations, args.resolution)
    g = scene.geometry
    shape = g.section + (f" {g.airfoil}" if g.section == "naca4" else "") + (
        f", wall {g.wall:g} m" if g.wall else "")
    lines = [f"fxflex section   scene {scene.hash}   {shape}, {len(rows)} stations "
             f"(centroid and shear centre in m: outline coordinates / from the centroid)",
             f"{'x m':>8} {'A m^2':>11} {'centroid':>21} {'Iy m^4':>11} {'Iz m^4':>11} "
             f"{'Iyz m^4':>11} {'princ deg':>9} {'J m^4':>11} {'shear centre':>21} "
             f"{'kg/m':>9}"]
    for r in rows:
        lines.append(f"{r['x']:8.4g} {r['A']:11.5g} {r['centroid'][0]:+10.4g},"
                     f"{r['centroid'][1]:+10.4g} {r['Iy']:11.5g} {r['Iz']:11.5g} "
                     f"{r['Iyz']:+11.4g} {r['principal_deg']:+9.4f} {r['J']:11.5g} "
                     f"{r['shear_centre'][0]:+10.4g},{r['shear_centre'][1]:+10.4g} "
                     f"{r['mass_per_length']:9.4g}")
    if args.plot:
        from fxflex.section.figures import plot_sections

        files = _agreed(comm, plot_sections, scene, rows, args.plot, args.resolution,
                        enabled=comm.rank == 0)
        lines.append(f"plots: {len(files or [])} PNG files in {args.plot}")
    _emit(comm, args, envelope(scene, stations=rows), "\n".join(lines))


def cmd_cache(args, comm) -> None:
    """``fxflex cache info|clear [--kind KIND]``: the folder (``$FXFLEX_CACHE`` or
    ~/.cache/fxflex), what each kind holds, and whether ``FXFLEX_NO_CACHE`` bypasses it."""
    from fxflex import cache
    from fxflex.io import envelope
    from fxflex.scene import Scene

    if args.kind and args.action != "clear":
        raise FxflexError("--kind: only with 'clear' (info lists every kind)")
    kinds = cache.usage()
    removed = None
    if args.action == "clear":
        removed = cache.clear(args.kind) if comm.rank == 0 else {}
        comm.Barrier()
        kinds = cache.usage()
    payload = envelope(Scene(), cache_dir=str(cache.cache_root()),
                       enabled={k: cache.enabled(k) for k in cache.KINDS},
                       kinds=kinds, removed=removed)
    lines = [f"fxflex cache: {cache.cache_root()}"]
    if removed is not None:
        freed = sum(v["bytes"] for v in removed.values())
        lines.append(f"  removed {sum(v['files'] for v in removed.values())} file(s), "
                     f"{freed / 2**20:.1f} MiB" + (f" of kind {args.kind}" if args.kind else ""))
    for kind, what in cache.KINDS.items():
        k = kinds.get(kind, {"files": 0, "bytes": 0})
        off = "" if cache.enabled(kind) else " [bypassed: FXFLEX_NO_CACHE]"
        lines.append(f"  {kind:15s} {k['files']:5d} file(s) {k['bytes'] / 2**20:9.1f} MiB   "
                     f"{what}{off}")
    _emit(comm, args, payload, "\n".join(lines))


COMMANDS = {"cache": cmd_cache, "info": cmd_info, "steady": cmd_steady, "run": cmd_run,
            "modes": cmd_modes, "compare": cmd_compare, "bench": cmd_bench,
            "section": cmd_section}


def _quiet_logs() -> None:
    """Warnings and errors only on stderr: FFCx's JIT and its C compiler log at INFO through
    loggers that set their own level (setuptools even adds its own root handler on a cold JIT
    cache), so INFO is disabled outright and the handler filters too."""
    logging.disable(logging.INFO)
    handler = logging.StreamHandler(sys.stderr)
    handler.setLevel(logging.WARNING)
    handler.setFormatter(logging.Formatter("fxflex: %(levelname)s: %(message)s"))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(logging.WARNING)
    for name in ("ffcx", "UFL", "ufl", "dolfinx", "FFCX"):
        logging.getLogger(name).setLevel(logging.WARNING)


def main(argv: list[str] | None = None) -> int:
    # Open MPI's banner on MPI_Abort (ten lines around our one) is a help message of the
    # aborting process; quiet mode, read at MPI initialisation, keeps it out
    os.environ.setdefault("OMPI_MCA_orte_execute_quiet", "1")
    _quiet_logs()
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    if comm.rank != 0:              # warnings are the same on every rank: rank 0 prints them
        logging.getLogger().handlers[0].setLevel(logging.ERROR)
    agree = comm.Dup() if comm.size > 1 else None
    try:
        args = make_parser().parse_args(argv)
        COMMANDS[args.command](args, comm)
    except SystemExit as exc:       # --help, --version, or a command's own status
        status = int(exc.code or 0) if not isinstance(exc.code, str) else EXIT_INPUT
        return _fail(comm, agree, None, status) if status else 0
    except BaseException as exc:
        return _fail(comm, agree, *_describe(exc))
    finally:
        if agree is not None:
            agree.Free()
    return 0


def _describe(exc: BaseException) -> tuple[str, int]:
    """The one line an exception is reported with, and the exit status."""
    if isinstance(exc, FxflexError):
        return f"fxflex: error: {exc}", exc.status
    if isinstance(exc, KeyboardInterrupt):
        return "fxflex: interrupted", EXIT_INTERRUPT
    if isinstance(exc, MemoryError):
        return ("fxflex: error: out of memory: the scene's mesh or model is too large for this "
                "machine (reduce mesh.solid, mesh.beam_elements or the number of modes)",
                EXIT_INPUT)
    if isinstance(exc, OSError) and exc.filename:
        return f"fxflex: error: {exc.filename}: {exc.strerror or exc}", EXIT_FAILURE
    if os.environ.get("FXFLEX_TRACEBACK"):
        traceback.print_exception(type(exc), exc, exc.__traceback__)
    return (f"fxflex: error: unexpected {type(exc).__name__}: {exc} (FXFLEX_TRACEBACK=1 shows "
            "where)", EXIT_FAILURE)


def _fail(comm, agree, line: str | None, status: int) -> int:
    """Report an error once and end every rank with ``status``.

    Serially: print ``line``, return ``status``. Under MPI the failing ranks meet in a
    non-blocking barrier on their own communicator (``agree``): when every rank arrives within
    ``AGREE_S`` the error was collective (bad input every rank found, an output failure that was
    broadcast) and rank 0 reports it; a rank still alone after that is the only one that failed
    while the others wait in a collective for it, and reports it itself. The reporting rank
    prints the line and ends the job with MPI_Abort: unlike ranks leaving with a non-zero status,
    which mpirun follows with two banners, an abort in quiet mode adds nothing to the line."""
    if agree is None:
        _print(line)
        return status
    request = agree.Ibarrier()
    deadline = time.monotonic() + AGREE_S
    alone = False
    while not request.Test():
        if time.monotonic() > deadline:
            alone = True
            break
        time.sleep(0.005)
    if alone or comm.rank == 0:
        _print(line)
        comm.Abort(status)
    agree.Barrier()                 # rank 0 aborts the job meanwhile
    return status


def _print(line: str | None) -> None:
    if line:
        sys.stderr.write(line + "\n")
        sys.stderr.flush()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
