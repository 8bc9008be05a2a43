"""Quadratic tetrahedra against Q2 hexahedra on the default blade (issue 14, docs/sections.md).

Both sides use what an imported mesh uses (SPEC section 9): the line load as the volume force
q / A(X) and the tip deflection as the tip face's area-weighted mean. The hexahedra are the
built-in mesh of the paper's rectangle given as a polygon section (which switches the built-in
mesh to those conventions; tests/mesh/test_imported.py shows its exported copy gives the same
results to 1e-8), on the levels (8 k, 2 k, 2 k) (the scene wants even Y and Z divisions),
extrapolated per component by Richardson from the three finest
(:func:`fxflex.analysis.reference.extrapolate`); the tetrahedra are
:func:`fxflex.mesh.tetra.write_tet_blade` meshes of decreasing size, their error taken against
that extrapolation, their observed order the least-squares slope against the mean cell size
(V / cells)^(1/3). Per mesh: TLF's steady state and its four lowest frequencies at the scene's
speed, and central difference's critical step with the lumped mass (row sums on Q2, HRZ on the
quadratic tetrahedra) from the clamped body's w_max.

    python -m fxflex.bench.tets [--rpm 1000] [--sizes 0.04,0.03,0.02] [--levels 2,3,4]

Serial; prints a Markdown table.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fxflex.scene import Scene

__all__ = ["hex_scene", "tet_scene", "measure", "main"]


def hex_scene(folder: Path, k: int, rpm: float) -> Scene:
    """The default blade as a polygon section, Q2 on level k (module docstring)."""
    g = Scene().geometry
    contour = Path(folder) / "rectangle.csv"
    y, z = g.root_y / 2, g.root_z / 2
    # every rank of a parallel run writes the same file: in one step (a temporary, then
    # os.replace), so that no rank reads another's half-written (truncated) copy
    tmp = contour.with_name(f"{contour.name}.{os.getpid()}.tmp")
    tmp.write_text("y,z\n" + "".join(f"{a},{b}\n" for a, b in
                                     ((-y, -z), (y, -z), (y, z), (-y, z))))
    os.replace(tmp, contour)
    return Scene().replace(**{"geometry.section": "polygon", "geometry.contour": str(contour),
                              "mesh.solid": (8 * k, 2 * k, 2 * k), "mesh.solid_degree": 2,
                              "rotation.rpm": rpm})


def tet_scene(path: Path, order: int, rpm: float) -> Scene:
    """The default blade on the tetrahedral file ``path`` of ``order``."""
    return Scene().replace(**{"mesh.solid_file": str(path), "mesh.solid_degree": order,
                              "rotation.rpm": rpm})


def measure(scene: Scene, comm=MPI.COMM_SELF) -> dict:
    """TLF on ``scene``: steady tip (m), four lowest frequencies (Hz), lumped w_max (rad/s) and
    central difference's critical step (s), unknowns, cells and wall times."""
    from dolfinx import fem

    from fxflex.analysis.modes import modes_of
    from fxflex.formulation import BuildOptions, build
    from fxflex.time.step_stability import critical_step

    t0 = time.perf_counter()
    form = build("tlf", scene, comm, BuildOptions(mass="lumped"))
    tip = form.steady_state().tip
    t1 = time.perf_counter()
    freqs = np.asarray(modes_of(form, 4).frequencies_hz)
    t2 = time.perf_counter()
    w = form.omega_max()
    model = form.model
    cells = comm.allreduce(model.mesh.topology.index_map(3).size_local)
    volume = comm.allreduce(fem.assemble_scalar(fem.form(1.0 * model.dx)))
    d = scene.damping.c / scene.material.rho
    return {"dof": form.dof, "cells": cells, "size": (volume / cells) ** (1.0 / 3.0),
            "tip": np.asarray(tip), "freqs": freqs, "w_max": w,
            "dt_cd": critical_step("cd", w, d), "steady_s": t1 - t0, "modes_s": t2 - t1}


def main(argv=None) -> None:
    from fxflex.analysis.convergence import fitted_order
    from fxflex.analysis.reference import extrapolate, relative_error
    from fxflex.mesh.tetra import write_tet_blade

    parser = argparse.ArgumentParser(prog="python -m fxflex.bench.tets")
    parser.add_argument("--rpm", type=float, default=1000.0)
    parser.add_argument("--sizes", default="0.04,0.03,0.02")
    parser.add_argument("--levels", default="2,3,4")
    args = parser.parse_args(argv)
    sizes = [float(s) for s in args.sizes.split(",")]
    levels = [int(m) for m in args.levels.split(",")]
    folder = Path(tempfile.mkdtemp(prefix="tet-study-"))
    rows = []
    for k in levels:
        rows.append(("Q2 hex", f"{8 * k}x{2 * k}x{2 * k}",
                     measure(hex_scene(folder, k, args.rpm))))
    hexes = np.array([r[2]["tip"] for r in rows])
    ref = np.array(extrapolate(levels, hexes)["extrapolated_m"], float)
    f_ref = rows[-1][2]["freqs"]
    g = Scene().geometry
    for size in sizes:
        path = write_tet_blade(g, folder / f"tet-{size}.msh", size, order=2)
        rows.append(("P2 tet", f"size {size}", measure(tet_scene(path, 2, args.rpm))))
    print(f"rpm {args.rpm:g}; reference (Q2 Richardson, levels {levels}): tip "
          f"{np.round(1e3 * ref, 6).tolist()} mm; frequencies vs the finest Q2")
    print("| mesh | | unknowns | cells | mean size m | tip mm | error vs reference | "
          "frequency gaps % | w_max rad/s | CD critical step us | steady s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for kind, name, r in rows:
        gaps = np.round(100 * (r["freqs"] / f_ref - 1.0), 3).tolist()
        print(f"| {kind} | {name} | {r['dof']} | {r['cells']} | {r['size']:.4f} | "
              f"{np.round(1e3 * r['tip'], 5).tolist()} | {relative_error(r['tip'], ref):.2e} | "
              f"{gaps} | {r['w_max']:.4g} | {1e6 * r['dt_cd']:.4g} | {r['steady_s']:.1f} |")
    tets = [r for kind, _, r in rows if kind == "P2 tet"]
    if len(tets) >= 2:
        err = [relative_error(r["tip"], ref) for r in tets]
        order = fitted_order([1.0 / r["size"] for r in tets], err)
        print(f"P2 tet observed order (tip, least squares over {len(tets)} sizes): {order:.2f}")
    hex_err = [relative_error(r["tip"], ref) for kind, _, r in rows if kind == "Q2 hex"]
    print(f"Q2 hex errors vs their extrapolation: {[f'{e:.1e}' for e in hex_err]}")


if __name__ == "__main__":
    main()
