"""A converged reference for the convergent (steady-state) deflections of a scene (issue 7).

The convergent deflection (SPEC sections 2 and 6) is the rotating-frame equilibrium. Its exact
value for the 3-D continuum is estimated here, for two theories:

- ``tlf``: the nonlinear equilibrium (St.Venant-Kirchhoff, Green-Lagrange strain, centrifugal
  load on the deformed position; paper Eq. 30-33 at constant speed), solved by
  :func:`fxflex.solid.tlf.tlf_steady` -- the truth every method is measured against;
- ``linear``: the small-strain equilibrium (K_L - Omega^2 M_P) U = F + Omega^2 f_c (Eq. 59 without
  time derivatives), :func:`fxflex.solid.small_strain.linear_steady` -- the continuum that FFRF, GCMS and
  LEBB approximate, so that their discretisation error is separated from their model error.

Discretisation. Two families of meshes of the same shape, (nx, ny, nz) = (16 m, 2 m, m): cells of
0.0625 x 0.06 x 0.06 m / m at the root, like the paper's 0.01 m cubes at m = 6 (its mesh is
100 x 12 x 6, i.e. nx = 100 instead of 96):

- isoparametric Q2 (27-node hexahedra, 3x3x3 Gauss) at m = 3, 4, 6, 8 (26208 to 430848 unknowns):
  the reference. The beam is twisted (-45 deg over 1 m), so a trilinear geometry would cap the
  convergence at second order (its volume error falls as h^2, ``docs/steady.md``); the quadratic
  interpolant of the exact shape (``build_solid_mesh(order=2)``) makes the volume error fall as
  h^4 (measured), below the displacement error at every level here;
- Q1 (the paper's element, 2x2x2 Gauss) at m = 4, 6, 8, 12 (8640 to 187200 unknowns): an
  independent check of the extrapolated value.

Richardson extrapolation, per component: three levels h_1 > h_2 > h_3 (h = 1 / m) with values f_i
give the observed order p from (f_1 - f_2) / (f_2 - f_3) = (h_1^p - h_2^p) / (h_2^p - h_3^p) (a
root in p, the ratios of h being unequal) and the extrapolated value f = f_3 - C h_3^p with
C = (f_2 - f_3) / (h_2^p - h_3^p). It needs monotone convergence (same-sign differences); a
component that does not converge monotonically keeps the finest value. The reference is the Q2
extrapolation from its three finest levels; its error estimate per component is the largest of
|Q2 extrapolation - the one from the three coarser Q2 levels| and |Q2 extrapolation - Q1
extrapolation| (or, without an extrapolation, the last change between levels).

The computed reference is stored as JSON with the command that produced it (``fxflex bench
accuracy --reference``); :func:`stored_reference` finds the stored one for a scene by
:func:`reference_key`, a hash of only what the equilibrium depends on.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from fxflex.scene import PAPER_RPM, Scene

__all__ = ["THEORIES", "FAMILIES", "QUICK_FAMILIES", "STORE", "divisions", "richardson",
           "extrapolate", "equilibrium_levels", "converged_reference", "reference_key",
           "stored_reference", "save_reference", "relative_error"]

THEORIES = ("tlf", "linear")
#: element family -> (degree, levels m of the (16 m, 2 m, m) meshes, coarse to fine)
FAMILIES = {"Q2": (2, (3, 4, 6, 8)), "Q1": (1, (4, 6, 8, 12))}
#: a smoke version (seconds): same method, coarse levels
QUICK_FAMILIES = {"Q2": (2, (1, 2, 3)), "Q1": (1, (2, 4, 6))}
#: the stored reference of the default scene
STORE = Path(__file__).resolve().parents[1] / "data" / "reference.json"
COMPONENTS = ("longitudinal", "orthogonal", "load")


def divisions(m: int) -> tuple[int, int, int]:
    """The level-m mesh of both families: 16 m x 2 m x m hexahedra."""
    return 16 * m, 2 * m, m


def relative_error(tip, ref) -> float:
    """|U - U_ref| / |U_ref| for tip deflection vectors (the error of a convergent deflection)."""
    ref = np.asarray(ref, float)
    return float(np.linalg.norm(np.asarray(tip, float) - ref) / np.linalg.norm(ref))


def richardson(h, f) -> tuple[float | None, float | None]:
    """(observed order p, extrapolated value) from three levels h_1 > h_2 > h_3 (module
    docstring); (None, None) when the differences change sign or vanish, or no order in
    (0.05, 12) fits."""
    h1, h2, h3 = (float(x) for x in h)
    f1, f2, f3 = (float(x) for x in f)
    d12, d23 = f1 - f2, f2 - f3
    if d12 == 0.0 or d23 == 0.0 or (d12 > 0) != (d23 > 0):
        return None, None
    ratio = d12 / d23

    def gap(p):
        return (h1**p - h2**p) / (h2**p - h3**p) - ratio

    lo, hi = 0.05, 12.0
    if gap(lo) * gap(hi) > 0:
        return None, None
    p = brentq(gap, lo, hi, xtol=1e-10)
    c = d23 / (h2**p - h3**p)
    return float(p), float(f3 - c * h3**p)


def extrapolate(levels: list[int], tips: np.ndarray) -> dict:
    """Richardson per component from the three finest levels and, with four or more, from the
    three before them. ``tips`` (n_levels, 3), levels m ascending."""
    h = 1.0 / np.asarray(levels, float)
    tips = np.asarray(tips, float)
    out = {"order": [], "extrapolated_m": [], "previous_order": [], "previous_m": []}
    for k in range(3):
        p, value = richardson(h[-3:], tips[-3:, k])
        out["order"].append(p)
        out["extrapolated_m"].append(value)
        p0, v0 = richardson(h[-4:-1], tips[-4:-1, k]) if len(levels) >= 4 else (None, None)
        out["previous_order"].append(p0)
        out["previous_m"].append(v0)
    return out


def _combine(q2: dict, q1: dict, q2_tips: np.ndarray) -> tuple[list[float], list[float]]:
    """Reference value and error estimate per component (module docstring)."""
    value, error = [], []
    for k in range(3):
        v = q2["extrapolated_m"][k]
        if v is None:                                   # not monotone: finest level
            v = float(q2_tips[-1, k])
            error.append(float(abs(q2_tips[-1, k] - q2_tips[-2, k])))
        else:
            others = [x for x in (q2["previous_m"][k], q1["extrapolated_m"][k]) if x is not None]
            error.append(float(max((abs(v - x) for x in others),
                                   default=abs(v - q2_tips[-1, k]))))
        value.append(float(v))
    return value, error


def equilibrium_levels(scene: Scene, comm, families: dict, speeds, theories=THEORIES,
                       log=None) -> list[dict]:
    """Solve both theories at every speed on every level of ``families``; one row per (family,
    level, theory, speed) with the tip (m), unknowns, Newton iterations and wall times. One mesh
    and function space per level serves every speed and theory."""
    from fxflex.solid.small_strain import linear_steady
    from fxflex.solid.model import SolidModel
    from fxflex.solid.tlf import tlf_steady

    # rtol 1e-9: on the finest Q2 levels the residual's round-off floor is about 1.2e-10 of the
    # first residual, where 1e-10 would cost an iteration that cannot improve it
    options = {"tlf": {"rtol": 1e-9}, "linear": {}}
    rows = []
    for family, (degree, levels) in families.items():
        for m in levels:
            t0 = time.perf_counter()
            model = SolidModel(scene, comm, divisions=divisions(m), degree=degree)
            built = time.perf_counter() - t0
            for theory in theories:
                solve = tlf_steady if theory == "tlf" else linear_steady
                for rpm in speeds:
                    t1 = time.perf_counter()
                    st = solve(model, rpm * math.pi / 30.0, **options[theory])
                    wall = time.perf_counter() - t1
                    if not st.converged:
                        raise RuntimeError(f"{theory} equilibrium on {family} m = {m} at {rpm} "
                                           f"rpm did not converge")
                    row = {"family": family, "degree": degree, "m": m,
                           "divisions": list(divisions(m)), "theory": theory, "rpm": float(rpm),
                           "dof": model.dof, "tip_m": [float(x) for x in st.tip],
                           "iterations": st.iterations, "build_s": built, "solve_s": wall}
                    rows.append(row)
                    if log is not None:
                        log(f"  {family} m={m} ({model.dof} unknowns) {theory} {rpm:g} rpm: "
                            f"tip {np.round(1e3 * st.tip, 6)} mm, {st.iterations} it, "
                            f"{wall:.1f} s")
    return rows


def summarise(rows: list[dict], families: dict) -> dict:
    """Per theory and speed: the levels, Richardson per family, the reference and its error."""
    out: dict = {}
    for theory in sorted({r["theory"] for r in rows}):
        out[theory] = {}
        for rpm in sorted({r["rpm"] for r in rows if r["theory"] == theory}):
            entry = {}
            tips = {}
            for family, (_, levels) in families.items():
                sel = sorted((r for r in rows if r["theory"] == theory and r["rpm"] == rpm
                              and r["family"] == family), key=lambda r: r["m"])
                tips[family] = np.array([r["tip_m"] for r in sel])
                entry[family] = extrapolate([r["m"] for r in sel], tips[family])
            value, error = _combine(entry["Q2"], entry["Q1"], tips["Q2"])
            entry["reference_m"] = value
            entry["error_estimate_m"] = error
            entry["relative_error_estimate"] = float(np.linalg.norm(error)
                                                     / np.linalg.norm(value))
            out[theory][f"{rpm:g}"] = entry
    return out


def reference_key(scene: Scene) -> str:
    """Hash of what the equilibrium depends on: geometry, material, the loads and, for the
    absolute damping model, the damping (the relative model's equilibrium does not depend on c;
    neither depends on meshes, modes, speeds, ramp or integrator). The section keys of SPEC
    section 9 and the tip mass of section 10 count only away from their defaults
    (:meth:`Scene.stable_dict`); the contour and stations files by their bytes
    (:meth:`Scene.file_digests`)."""
    d = scene.stable_dict()
    what = {"geometry": d["geometry"], "material": d["material"],
            "load": {k: d["load"][k] for k in ("line_load", "tip_force")}}
    if scene.damping.model == "absolute" and scene.damping.c > 0:
        what["damping"] = d["damping"]
    if "tip_mass" in d:                         # its centrifugal force moves the equilibrium
        what["tip_mass"] = d["tip_mass"]
    files = scene.file_digests("geometry")      # the blade is the files' text, not their paths
    if files:
        what["files"] = files
    text = json.dumps(what, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def converged_reference(scene: Scene, comm, *, speeds=PAPER_RPM, quick: bool = False,
                        log=None) -> dict:
    """Compute the reference of ``scene`` at ``speeds`` (rpm): every level, the Richardson
    extrapolations and the reference with its error estimate (module docstring)."""
    from fxflex import __version__
    from fxflex.io.machine import machine

    families = QUICK_FAMILIES if quick else FAMILIES
    t0 = time.perf_counter()
    load0 = os.getloadavg()[0]
    rows = equilibrium_levels(scene, comm, families, speeds, log=log)
    return {"key": reference_key(scene), "quick": quick, "fxflex_version": __version__,
            "machine": machine(), "load_start": load0, "load_end": os.getloadavg()[0],
            "ranks": comm.size, "wall_s": time.perf_counter() - t0,
            "families": {k: {"degree": d, "levels": list(m)} for k, (d, m) in families.items()},
            "levels": rows, "theories": summarise(rows, families)}


def stored_reference(scene: Scene, path: Path | str = STORE) -> dict | None:
    """The stored reference computed for this scene's equilibrium (same :func:`reference_key`),
    or None."""
    try:
        with open(path) as fh:
            data = json.load(fh)
    except (OSError, ValueError):
        return None
    return data if data.get("key") == reference_key(scene) else None


def save_reference(data: dict, path: Path | str) -> None:
    """Write atomically (a reader sees the old file or the new one)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    with open(tmp, "w") as fh:
        json.dump(data, fh, indent=1)
        fh.write("\n")
    os.replace(tmp, path)
