"""Accuracy on request: refine a method's discretisation until its estimated error is below EPS
(SPEC section 9 "Accuracy on request", issue 15; ``fxflex steady --tol``, ``fxflex modes --tol``).

The estimate is of the discretisation error of the method's own continuum (beam theory for the
beams, the linear continuum for FFRF, GCMS and LEBB, the nonlinear one for TLF): the model error
between theories is what ``fxflex compare`` is for.

Refinement ladder per method (:func:`ladder`), cheap first, only through existing scene keys:

- LEBB: ``mesh.beam_elements`` 2, 4, then the counts the convergence asks for (uniform
  Euler-Bernoulli beam; converges as h^2, docs/convergence_measured.md). Its Hermite spaces
  nest, so on the paper's shape the 2-element level is solved on the 4-element level's
  operators restricted to its subspace (:meth:`Refiner.nested`; the same discretisation to
  1e-13 of |tip|; station tables and hollow walls would differ by their quadrature): a build
  fewer, most of a LEBB level's cost;
- NEBB, ANCF: ``mesh.beam_variant = "locking-free"`` (unless the scene sets another variant than
  the default "paper" -- a scene that names "paper" explicitly is the default and is refined
  locking-free too), elements 2, 4, then as LEBB (ANCF from 2, not 5, since 2026-12-06: its
  2-4-8-16 levels reached EPS at a third to a half of the 5-10-20 levels' cost; NEBB from 2,
  not 4, with the predicted levels; docs/tolerance.md). From the third level on a beam level
  is not a doubling but the count the levels so far ask for (:func:`next_elements`: the last
  level's estimated error and order, aiming at AIM EPS, within JUMP times the last count), so
  that the level that meets EPS is not up to twice the size needed (steady states only: the
  frequencies keep the doublings, whose Richardson triples leave the coarse levels behind);
  NEBB starts each level's Newton iteration from the coarser level's equilibrium
  (:meth:`Refiner._seed`);
- TLF, FFRF, GCMS: ``mesh.solid_degree = 2`` (27-node hexahedra) on ``mesh.solid`` =
  8x2x2, 16x2x2, 32x4x2, 48x6x4, 64x8x4, 96x12x6 (Y and Z divisions stay even, SPEC 8). FFRF and
  GCMS solve every mesh at 2 n modes (``reduction.ffrf_modes`` / ``gcms_modes``, n the scene's,
  at least :data:`MIN_MODES`) and take the result at n from the first n of the same clamped
  modes (:meth:`Refiner.truncated`: one eigensolve, one more projection): the mode-count
  difference |f_n - f_2n| estimates the truncation error of f_n, an upper estimate of that of
  the 2 n result returned, on that mesh. It is an estimate, not a bound: a family that neither
  count holds (no axial mode in 2 or 4 modes) changes nothing between them, hence the floor
  MIN_MODES. A level is accepted when the mesh estimate plus the mode-count difference of the
  finest mesh is below EPS. Where it is not, and the mode-count difference is both at least
  EPS / 2 and at least the mesh estimate (the count, not the mesh, is short), n is doubled and
  the ladder starts again from its first mesh (at most MODE_DOUBLINGS times, while 4 n modes
  fit the first mesh; then the ladder stops there: a finer mesh cannot help). A first mesh that
  the scene refuses (too few ANCF elements for its twist, more modes than unknowns) is skipped.

Error estimate (:func:`estimate`), per component from the successive levels with h = 1 / (elements
along the span): with three levels whose differences have one sign and shrink, and whose observed
order p (:func:`fxflex.analysis.reference.richardson`) lies in [MIN_ORDER, MAX_ORDER], the
estimate is |f_3 - f_Richardson| ("richardson"; for the solids' frequencies with the order
capped at :data:`SOLID_MODES_ORDER`); otherwise the difference of the last two levels
|f_3 - f_2| ("difference"); a tip component's reported "difference" is at least the largest
component's estimate ("difference, the largest", :func:`share_largest`: a small component's
own difference says nothing of its order). The ladder's tests (stop, mode-count restart, the
next beam count) use the components' own estimates; sharing leaves the largest, and so a test
of every estimate against EPS, unchanged. Steady: each tip component relative to |tip| of the
finest level; modes: each frequency relative to itself. The result returned is the finest
level's (a real discretisation, not the extrapolation).

Newton to EPS: TLF's and NEBB's levels solve their equilibrium to a Newton residual of
NEWTON_EPS EPS relative to the load's (at least 1e-10, the default), not 1e-10: one iteration
fewer on most levels (TLF 5000 rpm, 1e-3: 0.64 -> 0.48 s), and the result moves by 1e-12 to 1e-9
of |tip| (quadratic convergence leaves far less than the bound). ANCF keeps the default
(:data:`LOOSE_NEWTON`).

Caps: ``max_levels`` levels (default the whole ladder) and ``max_dof`` unknowns (default
:data:`MAX_DOF`); a ladder that ends above EPS raises :class:`ToleranceNotMet`, which carries the
best result and names its estimate. Levels already computed are kept in the :class:`Refiner`'s
dict (the disk caches of meshes and modes help across runs).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from fxflex.analysis.reference import richardson
from fxflex.errors import FxflexError
from fxflex.scene import Scene, scene_from_dict

__all__ = ["COMPONENTS", "SOLID_LADDER", "MAX_DOF", "ToleranceNotMet", "ladder", "estimate",
           "share_largest",
           "Refiner", "steady_to_tolerance", "modes_to_tolerance", "json_fields", "shown",
           "DISCRETISATION_KEYS", "fixing_keys", "describe"]

COMPONENTS = ("longitudinal", "orthogonal", "load")
#: Q2 meshes (nx, ny, nz) of the solid methods, coarse to fine
SOLID_LADDER = ((8, 2, 2), (16, 2, 2), (32, 4, 2), (48, 6, 4), (64, 8, 4), (96, 12, 6))
#: beam element counts: first level and number of doublings (the second level doubles the
#: first; from the third on, the counts the convergence asks for: :func:`next_elements`)
BEAM_START = {"lebb": 2, "nebb": 2, "ancf": 2}
BEAM_LEVELS = 8
#: the order that sizes a beam level from two levels: the beams' tips converge as h^2
#: (docs/convergence_measured.md; frequencies faster, so the level overshoots)
BEAM_ORDER = 2.0
#: a predicted beam level aims at this share of EPS (a level that misses costs one more)
AIM = 0.5
#: a predicted beam level is at least 1.5 and at most 4 times the last (Richardson on close
#: levels amplifies their differences' round-off; a far jump from a pre-asymptotic estimate
#: overshoots); the last is the doubling ladder's (BEAM_START 2^(BEAM_LEVELS - 1))
JUMP = (1.5, 4.0)
#: at most this many predicted beam levels (1.5x each from 2 elements reaches 256 in 13)
MAX_PREDICTED = 16
#: default cap on the unknowns of a level (Q2 64x8x4 has 58752; 96x12x6 187200 is refused)
MAX_DOF = 100_000
#: a level's equilibrium is solved to a Newton residual of NEWTON_EPS EPS relative to the load's
#: (at least the default 1e-10): its error, of that relative size, stays far below the
#: discretisation error the ladder estimates (module docstring, "Newton to EPS")
NEWTON_EPS = 1e-4
#: the methods whose Newton residual is measured against the load's (TLF: the undeformed body's
#: residual; NEBB: the residual at W = 0). ANCF's dense Newton measures it against the residual
#: at x = 0, a collapsed body far larger than the load's, so 1e-6 of it left the tip 5.5e-5 off
#: (EPS 1e-2, 5000 rpm): ANCF keeps the default.
LOOSE_NEWTON = ("tlf", "nebb")
#: observed orders accepted for Richardson (the clamp singularity gives ~1.5 on Q2, beams 2)
MIN_ORDER, MAX_ORDER = 0.5, 8.0
#: the largest order the solids' frequency estimate uses: TLF's lowest six frequencies converge
#: at 1.5-1.7 on Q2 64x8x4 / 96x12x6 / 128x16x8 (3.1 for the 6th), while 32-48-64 show up to 6,
#: and Richardson with that order put the 6th frequency's estimate 7x below its error
#: (docs/tolerance.md)
SOLID_MODES_ORDER = 2.0
#: doublings of the mode count n (the ladder's meshes at n and 2 n modes; FFRF, GCMS)
MODE_DOUBLINGS = 3
SOLIDS = ("ffrf", "gcms", "tlf")
MODAL = {"ffrf": "ffrf_modes", "gcms": "gcms_modes"}
#: the smallest n of FFRF / GCMS's mode-count pairs (n, 2 n): the default counts, which hold the
#: axial stretch; below them both counts can miss a family (no axial mode at all), and their
#: difference then says nothing (module docstring)
MIN_MODES = {"ffrf": 30, "gcms": 90}


#: the scene keys that fix a method's spatial discretisation (``run --tol`` keeps a scene that
#: sets one of them, instead of refining as ``steady --tol`` would)
_SOLID_KEYS = ("mesh.solid", "mesh.solid_degree", "mesh.solid_file")
DISCRETISATION_KEYS = {"lebb": ("mesh.beam_elements",),
                       "nebb": ("mesh.beam_elements", "mesh.beam_variant"),
                       "ancf": ("mesh.beam_elements", "mesh.beam_variant"),
                       "tlf": _SOLID_KEYS,
                       "ffrf": _SOLID_KEYS + ("reduction.ffrf_modes",),
                       "gcms": _SOLID_KEYS + ("reduction.gcms_modes", "reduction.gcms_gram_tol")}


def fixing_keys(method: str, given: set[str]) -> list[str]:
    """The keys among ``given`` (dotted, those the user set) that fix the method's
    discretisation (DISCRETISATION_KEYS)."""
    return [k for k in DISCRETISATION_KEYS[method] if k in given]


class ToleranceNotMet(FxflexError):
    """The ladder ended (cap) above EPS; ``result`` is the best one reached (exit status 1)."""

    status = 1

    def __init__(self, message: str, result: dict):
        self.result = result
        super().__init__(message)


def ladder(method: str, scene: Scene, start: int | None = None) -> list[tuple[float, dict]]:
    """(h, scene overrides in TOML layout) per level, coarse first (module docstring); beams
    from ``start`` elements (default BEAM_START) doubling up to the last of the default ladder."""
    if method in SOLIDS:
        return [(1.0 / nx, {"mesh": {"solid_degree": 2, "solid": [nx, ny, nz]}})
                for nx, ny, nz in SOLID_LADDER]
    n0 = BEAM_START[method]
    last = n0 * 2 ** (BEAM_LEVELS - 1)
    mesh: dict = {}
    if method in ("nebb", "ancf"):
        variant = scene.mesh.beam_variant
        mesh["beam_variant"] = "locking-free" if variant == "paper" else variant
    counts, n = [], start or n0
    while n <= last:
        counts.append(n)
        n *= 2
    return [(1.0 / n, {"mesh": {**mesh, "beam_elements": n}}) for n in counts]


def next_elements(hs, values, err: np.ndarray, how: list[str], eps: float) -> int:
    """The beam element count the convergence so far asks for (module docstring): per quantity
    the error of the last level e (the Richardson estimate, or the last difference over
    (n_2 / n_1)^p - 1), the order p (Richardson's observed one within [1, 4], else BEAM_ORDER),
    and n (e / (AIM eps))^(1 / p); the largest, within JUMP times the last count."""
    n1, n2 = 1.0 / hs[-2], 1.0 / hs[-1]
    f = np.asarray(values, float)
    factor = 0.0
    for k, kind in enumerate(how):
        p, e = BEAM_ORDER, float(err[k])
        if kind.startswith("richardson"):
            q, _ = richardson(hs[-3:], f[-3:, k])
            p = min(max(q, 1.0), 4.0) if q is not None else p
        else:
            e /= (n2 / n1) ** p - 1.0
        factor = max(factor, (e / (AIM * eps)) ** (1.0 / p))
    lo, hi = JUMP
    return int(min(max(np.ceil(n2 * factor), np.ceil(lo * n2)), hi * n2))


def estimate(h, values, scale, order_cap: float | None = None) -> tuple[np.ndarray, list[str]]:
    """Per column of ``values`` (levels x quantities, h descending): the estimated error of the
    last level relative to ``scale`` (a number or one per quantity), and how ("richardson",
    "richardson, order P taken as CAP" or "difference"; module docstring). ``order_cap``: an
    observed order above it is taken as the cap, |f_3 - f_2| / ((h_2 / h_3)^cap - 1) (a
    pre-asymptotic order would shrink the estimate). Needs two levels or more."""
    h = np.asarray(h, float)
    f = np.asarray(values, float)
    if f.ndim == 1:
        f = f[:, None]
    if len(h) < 2:
        raise ValueError("estimate: needs two or more levels")
    scale = np.broadcast_to(np.abs(np.asarray(scale, float)), f.shape[1:])
    err, how = np.empty(f.shape[1]), []
    for k in range(f.shape[1]):
        kind, e = "difference", abs(f[-1, k] - f[-2, k])
        if len(h) >= 3:
            d12, d23 = f[-3, k] - f[-2, k], f[-2, k] - f[-1, k]
            p, value = richardson(h[-3:], f[-3:, k])
            capped = order_cap is not None and p is not None and p > order_cap
            if p is not None and abs(d23) < abs(d12) and MIN_ORDER <= p and (
                    p <= MAX_ORDER or capped):
                kind, e = "richardson", abs(f[-1, k] - value)
                if capped:                    # above MAX_ORDER too: the cap, not the difference
                    kind = f"richardson, order {p:.2g} taken as {order_cap:g}"
                    e = abs(d23) / ((h[-2] / h[-1]) ** order_cap - 1.0)
        err[k] = e / scale[k] if scale[k] > 0 else (0.0 if e == 0 else np.inf)
        how.append(kind)
    return err, how


def share_largest(err: np.ndarray, how: list[str]) -> tuple[np.ndarray, list[str]]:
    """Quantities on one scale (the tip components relative to |tip|): an estimate of kind
    "difference" below the largest is raised to it, "difference, the largest" (module
    docstring): its own difference bounds its error only if it converges at first order or
    faster, which no order checks (two levels, or three without one): TLF's orthogonal tip
    component, 200 times below the others, has an observed order of 0.35 on Q2 8x2x2 -> 16x2x2,
    and its difference was 3.6x below its error. The largest is unchanged, so is a test of
    every estimate against EPS."""
    err, how = np.array(err, float), list(how)
    top = float(np.max(err))
    for k, kind in enumerate(how):
        if kind == "difference" and err[k] < top:
            err[k], how[k] = top, "difference, the largest"
    return err, how


def describe(scene: Scene, method: str) -> dict:
    """The discretisation of a level (SPEC 9 ``discretisation`` keys)."""
    m = scene.mesh
    solid = method in SOLIDS
    return {"mesh": list(m.solid) if solid else None,
            "degree": m.solid_degree if solid else None,
            "modes": getattr(scene.reduction, MODAL[method]) if method in MODAL else None,
            "elements": None if solid else m.beam_elements,
            "variant": m.beam_variant if method in ("nebb", "ancf") else None}


class Refiner:
    """Solves levels of one method on one communicator and keeps them by scene (in-process reuse;
    ``steady`` and ``modes`` share the builds through the disk caches). The key is the frozen
    scene itself (its fields' equality and hash), not :attr:`Scene.hash`: that one serialises
    the scene and reads the files it names, a tenth of a millisecond a level, which a beam
    level of about one millisecond pays again at every level (files do not change within
    one command)."""

    def __init__(self, method: str, comm, options=None, pairs: int = 6):
        self.method, self.comm, self.options, self.pairs = method, comm, options, pairs
        self.done: dict[tuple[str, Scene], dict] = {}
        self._last: dict[str, object] = {}       # the last level's form per "steady" / "modes"
        #: Newton's relative residual for the levels' equilibria (None: the method's default;
        #: set by the ladder from EPS, NEWTON_EPS)
        self.steady_rtol: float | None = None

    def solve_to(self, rtol: float) -> None:
        """The Newton tolerance of the levels' equilibria (NEWTON_EPS; TLF, NEBB only): levels
        kept from another tolerance are dropped, not reused."""
        if self.method in LOOSE_NEWTON and rtol != self.steady_rtol:
            self.done.clear()
            self._last.clear()
            self.steady_rtol = rtol

    def level(self, scene: Scene, what: str) -> dict:
        """One level: ``what`` = "steady" (tip, m) or "modes" (frequencies, Hz)."""
        from fxflex.formulation import build

        key = (what, scene)
        if key in self.done:
            return self.done[key]
        t0 = time.perf_counter()
        form = build(self.method, scene, self.comm, self.options)
        if self.steady_rtol is not None:                # set by solve_to: TLF, NEBB
            form.steady_rtol = self.steady_rtol
        if self.method in ("tlf", "nebb"):
            self._seed(form, what)
        return self._evaluate(key, scene, form, t0)

    def _seed(self, form, what: str) -> None:
        """TLF, NEBB: start the equilibrium from the previous level's, prolongated to this mesh
        (nested iteration; TLF: one Newton continuation of about three iterations instead of
        the stages from the undeformed body, :func:`fxflex.solid.tlf_steady.prolongate`; NEBB:
        two or three Newton iterations instead of four, the coarse level's Hermite interpolant
        at the new nodes, :meth:`fxflex.beam.frame.FloatingFrameBeam.prolongate`)."""
        previous = self._last.get(what)
        steady = getattr(previous, "_steady", None)
        if steady is None or not steady.converged:
            return
        if any(getattr(previous.scene, f.name) != getattr(form.scene, f.name)
               for f in dataclasses.fields(Scene) if f.name != "mesh"):
            return                              # another scene than this ladder's: no guess
        if self.method == "nebb":
            if previous.variant == form.variant:
                form.steady_start = previous.prolongate(steady.q, form.line.x_nodes)
            return
        from fxflex.solid.tlf_steady import prolongate

        U0 = prolongate(previous.model, steady.q, form.model)
        if U0 is not None:
            form.steady_start = (form.scene.rotation.omega, U0)

    def nested(self, scene: Scene, finer: Scene) -> Scene:
        """LEBB steady: the level of ``finer`` (a mesh that refines ``scene``'s), built and
        solved, and the level of ``scene`` from it by restriction to the coarse Hermite
        subspace (:meth:`~fxflex.beam.frame.FloatingFrameBeam.restricted_steady`: on the
        paper's shape the same discretisation, to 1e-13 of |tip|, without a build of its own,
        which is most of a LEBB level's cost); both kept for :meth:`level`. Returns
        ``finer``."""
        if ("steady", scene) in self.done:
            return finer
        fine = self.level(finer, "steady")
        t0 = time.perf_counter()
        st = fine["form"].restricted_steady(scene.mesh.beam_elements)
        self.done[("steady", scene)] = {
            "discretisation": describe(scene, self.method), "dof": st.q.size,
            "result": [float(x) for x in st.tip], "seconds": time.perf_counter() - t0,
            "build_s": 0.0, "form": None, "steady": st}
        return finer

    def truncated(self, scene: Scene, what: str, source: dict) -> dict:
        """The level of ``scene`` whose mode count is below that of ``source`` (a level of the
        same mesh, FFRF / GCMS): built on the source's mesh, operators and clamped modes, of
        which it takes the first ones, so that a mode-count difference costs one eigensolve
        (the larger) and one more projection."""
        key = (what, scene)
        if key in self.done:
            return self.done[key]
        t0 = time.perf_counter()
        big = source["form"]
        form = type(big)(scene, self.comm, big.options, model=big.model, data=big.data,
                         modes=big.modes)
        form.options = big.options
        return self._evaluate(key, scene, form, t0)

    def _evaluate(self, key, scene: Scene, form, t0: float) -> dict:
        t1 = time.perf_counter()
        if key[0] == "steady":
            st = form.steady_state()
            if not st.converged:
                raise FxflexError(f"--tol: the {self.method} equilibrium on "
                                  f"{describe(scene, self.method)} did not converge")
            if self.method in LOOSE_NEWTON:       # what it was solved to (NEWTON_EPS)
                st.extra["newton_rtol"] = form.steady_rtol
            values = [float(x) for x in st.tip]
            extra = {"steady": st}
        else:
            from fxflex.analysis.modes import modes_of
            modes = modes_of(form, self.pairs)
            values = [float(x) for x in modes.frequencies_hz]
            extra = {"modes": modes}
        row = {"discretisation": describe(scene, self.method), "dof": form.dof,
               "result": values, "seconds": time.perf_counter() - t0,
               "build_s": t1 - t0, "form": form, **extra}
        self.done[key] = row
        self._last[key[0]] = form
        return row


def _public(row: dict, what: str) -> dict:
    name = "tip_m" if what == "steady" else "frequencies_hz"
    return {"discretisation": row["discretisation"], "dof": row["dof"], name: row["result"],
            "seconds": row["seconds"]}


def _refine(refiner: Refiner, scene: Scene, eps: float, what: str, max_levels: int | None,
            max_dof: int, log, predicted: bool = True) -> dict:
    method = refiner.method
    refiner.solve_to(float(f"{max(1e-10, NEWTON_EPS * eps):.3g}"))
    steps = ladder(method, scene)
    beam_steps = predicted and method not in SOLIDS and what == "steady"
    # the predicted beam levels may be more than the doublings' (1.5x a level at least): the
    # ladder then ends at its last count, not after len(steps) levels
    cap = max_levels or (MAX_PREDICTED if beam_steps else len(steps))
    if not beam_steps:
        cap = min(cap, len(steps))
    last = steps[-1][1]["mesh"].get("beam_elements")
    key = MODAL.get(method)                   # FFRF / GCMS: each mesh at n and 2 n modes
    count = max(getattr(scene.reduction, key), MIN_MODES[method]) if key else 0
    doublings, spent = 0, []                  # spent: the levels of a pass given up
    while True:
        hs, rows, levels, err, how = [], [], [], None, []
        mode_err = 0.0
        capped, restart, stopped = "the ladder's last level", False, False
        pending, used, made = list(steps), 0, None
        while pending and used < cap:
            h, overrides = pending.pop(0)
            used += 1
            if key:
                overrides = {**overrides, "reduction": {key: 2 * count}}
            level_scene = made or scene_from_dict(overrides, base=scene)
            made = None
            if _mesh_unknowns(method, level_scene) > max_dof and len(rows) >= 2:
                capped = f"the cap of {max_dof} unknowns"
                stopped = True
                break
            if not rows and _refused(method, level_scene, log):
                continue                      # too coarse for the scene: the next mesh
            if (not rows and method == "lebb" and what == "steady" and pending and used < cap
                    and scene.geometry.paper_shape and pending[0][1]["mesh"]["beam_elements"]
                    % level_scene.mesh.beam_elements == 0):
                # LEBB's first level from its second by restriction (nested Hermite spaces;
                # the paper's shape, whose section properties the two meshes integrate alike)
                made = refiner.nested(level_scene, scene_from_dict(pending[0][1], base=scene))
            row = refiner.level(level_scene, what)
            if rows and len(row["result"]) != len(rows[-1][0]["result"]):
                raise FxflexError(f"--tol: the {method} levels give different numbers of modes")
            if key:                           # the first n of the same clamped modes
                fewer = refiner.truncated(
                    scene_from_dict({"reduction": {key: count}}, base=level_scene), what, row)
                levels.append(_public(fewer, what))
                mode_err, _ = estimate([2.0, 1.0], [fewer["result"], row["result"]],
                                       _scale(row["result"], what))
            levels.append(_public(row, what))
            hs.append(h)
            rows.append((row, level_scene))
            if log is not None:
                log(f"--tol: {method} {row['discretisation']}: {row['dof']} unknowns, "
                    f"{row['seconds']:.2f} s")
            if len(rows) >= 2:
                values = [r["result"] for r, _ in rows]
                err, how = estimate(hs, values, _scale(values[-1], what),
                                    SOLID_MODES_ORDER if method in SOLIDS and what == "modes"
                                    else None)
                if np.all(err + mode_err < eps):
                    stopped = True
                    break
                if beam_steps:                # the next beam level: the count asked for
                    n = level_scene.mesh.beam_elements
                    pending = (ladder(method, scene, min(next_elements(hs, values, err, how,
                                                                       eps), last))
                               if n < last else [])
                if key and np.any((mode_err >= eps / 2.0) & (mode_err >= err)):
                    # the mode count, not the mesh, is what is short: a finer mesh cannot help
                    restart = doublings < MODE_DOUBLINGS and _pair_fits(
                        method, 4 * count, scene_from_dict(steps[0][1], base=scene))
                    if not restart:
                        capped = (f"{MODE_DOUBLINGS} doublings of the mode count"
                                  if doublings == MODE_DOUBLINGS else
                                  f"the mode counts the first mesh holds ({key} {2 * count})")
                    stopped = True
                    break
        if not stopped and max_levels and used == cap and pending:
            capped = f"the cap of {max_levels} levels"
        if not restart:
            break
        spent += levels
        count, doublings = 2 * count, doublings + 1
        if log is not None:
            log(f"--tol: {method} mode-count difference {float(np.max(mode_err)):.3g} >= EPS / 2: "
                f"{key} {2 * count} against {count}, from the first mesh")
    if err is None:
        raise FxflexError("--tol: the cap leaves one level; allowed: two levels or more")
    best, best_scene = rows[-1]
    # a given-up pass's 2 n levels are the next pass's n levels (the same builds): listed once
    listed: list = []
    for lv in spent + levels:
        if lv["discretisation"] not in [x["discretisation"] for x in listed]:
            listed.append(lv)
    levels = listed
    total = err + mode_err
    if what == "steady":                      # the ladder's tests above saw the own estimates
        total, how = share_largest(total, how)
    if key:
        how = [f"{k} + mode-count difference" for k in how]
    out = {"best": best, "scene": best_scene, "estimate": [float(x) for x in total],
           "how": how, "levels": levels,
           "discretisation": {**best["discretisation"], "levels": levels}}
    if not np.all(total < eps):
        worst = float(np.max(total))
        raise ToleranceNotMet(f"--tol {eps:g}: not reached within {capped}; best estimate "
                              f"{worst:.3g} on {shown(best['discretisation'])} "
                              f"({best['dof']} unknowns)", out)
    return out


def _refused(method: str, scene: Scene, log) -> bool:
    """Whether the scene refuses this level of the ladder (a first mesh too coarse for it: beam
    elements twisted by more than MAX_TWIST_PER_ELEMENT_DEG each, more modes than unknowns), so
    that the ladder starts at the next level; logged."""
    from fxflex.errors import SceneError
    from fxflex.scene.load import validate_for

    try:
        validate_for(method, scene)
        if method in ("lebb", "nebb"):         # their twist limit is checked at build
            from fxflex.beam.line import twist_check
            twist_check(scene, method)
    except SceneError as exc:
        if log is not None:
            log(f"--tol: {method} {describe(scene, method)} skipped: {exc}")
        return True
    return bool(MODAL.get(method)) and not _pair_fits(
        method, getattr(scene.reduction, MODAL[method]), scene)


def _pair_fits(method: str, count: int, scene: Scene) -> bool:
    """Whether ``count`` (``reduction.ffrf_modes`` / ``gcms_modes``) fits ``scene``'s mesh: its
    clamped modes (GCMS: count / 3) at most the mesh's unknowns."""
    clamped = count // 3 if method == "gcms" else count
    return clamped <= _mesh_unknowns(method, scene)


def shown(discretisation: dict) -> str:
    """``mesh [48, 6, 4], degree 2``: the keys of a discretisation that apply, on one line."""
    return ", ".join(f"{k} {v}" for k, v in discretisation.items()
                     if k != "levels" and v is not None)


def _mesh_unknowns(method: str, scene: Scene) -> int:
    """Unknowns of a level's mesh (Q2 with the root clamped: 3 (2 nx) (2 ny + 1) (2 nz + 1)); the
    beams' few hundred are never capped."""
    if method not in SOLIDS:
        return 0
    nx, ny, nz = scene.mesh.solid
    return 3 * (2 * nx) * (2 * ny + 1) * (2 * nz + 1)


def _scale(values, what: str):
    v = np.asarray(values, float)
    return np.linalg.norm(v) if what == "steady" else np.abs(v)


def steady_to_tolerance(method: str, scene: Scene, comm, eps: float, *, max_levels=None,
                        max_dof: int = MAX_DOF, refiner: Refiner | None = None,
                        log=None, predicted: bool = True) -> dict:
    """Refine until every tip component's estimated error relative to |tip| is below ``eps``.
    Returns ``best`` (the level: form, steady state, tip), ``scene`` (its scene), ``estimate``
    (per component), ``how``, ``levels`` and ``discretisation`` (SPEC 9); raises
    :class:`ToleranceNotMet` (with that dict) when a cap ends the ladder above ``eps``.
    ``predicted=False``: the beams' levels double (the fixed ladder of a reference)."""
    _check(eps)
    refiner = refiner or Refiner(method, comm)
    return _refine(refiner, scene, eps, "steady", max_levels, max_dof, log, predicted)


def modes_to_tolerance(method: str, scene: Scene, comm, eps: float, pairs: int, *, options=None,
                       max_levels=None, max_dof: int = MAX_DOF, log=None) -> dict:
    """As :func:`steady_to_tolerance` for the ``pairs`` lowest frequencies, each relative to
    itself; ``best`` carries the :class:`~fxflex.analysis.modes.Modes` of the level."""
    _check(eps)
    refiner = Refiner(method, comm, options, pairs)
    return _refine(refiner, scene, eps, "modes", max_levels, max_dof, log)


def json_fields(out: dict | None, what: str) -> dict:
    """SPEC 9 ``error_estimate`` and ``discretisation`` of a refinement (None: both null).
    Steady: an object per tip component; modes: a list, one per frequency. ``how`` says per
    entry whether it is a Richardson estimate or the difference of the last two levels."""
    if out is None:
        return {"error_estimate": None, "discretisation": None}
    est = out["estimate"]
    error = dict(zip(COMPONENTS, est)) if what == "steady" else list(est)
    return {"error_estimate": error,
            "discretisation": {**out["discretisation"], "estimate_kind": out["how"]}}


def _check(eps: float) -> None:
    if not (0.0 < eps < 1.0):
        raise FxflexError(f"--tol: got {eps:g}; allowed: 0 < EPS < 1 (a relative error)")
