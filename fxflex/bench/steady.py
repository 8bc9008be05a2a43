"""``fxflex bench steady``: where the time of the TLF steady state goes (issue 2).

Serial, in this process: mesh generation (cold and from the cache), function space and loads,
form compilation (FFCx JIT: first call and warm), residual and Jacobian assembly, one MUMPS
LDL^T factorisation, and the whole Newton solve at each paper speed. Then the same command
``fxflex steady --method tlf`` as whole processes, serial and under ``mpirun -n 2``.
Target: under 10 s per speed serial with a warm JIT cache.
"""

from __future__ import annotations

import json
import os

import numpy as np
import ufl
from dolfinx import fem

from fxflex.bench.common import Timer, machine, markdown_table, run_cli
from fxflex.errors import FxflexError
from fxflex.mesh.solid import build_solid_mesh
from fxflex.scene import PAPER_RPM, Scene
from fxflex.solid import forms
from fxflex.solid.model import SolidModel
from fxflex.solid.solvers import direct_solver
from fxflex.solid.tlf import tlf_steady

__all__ = ["run", "components"]


def components(scene: Scene, comm, repeats: int = 5) -> dict:
    """Time the pieces of one TLF steady solve at the scene's speed, in this process."""
    from dolfinx.fem.petsc import assemble_matrix, assemble_vector, create_matrix, create_vector

    out = {}
    with Timer() as t:
        build_solid_mesh(scene.geometry, scene.mesh.solid, comm, use_cache=False)
    out["mesh_generate_s"] = t.s
    with Timer() as t:
        model = SolidModel(scene, comm)
    out["model_from_cache_s"] = t.s
    out["mesh_from_cache_s"] = model.timings["mesh"]
    U = fem.Function(model.V)
    R = (forms.svk_residual(scene.material, U, model.u_test, model.dx)
         - scene.rotation.omega**2 * forms.centrifugal(model.rho, model.X0 + U, model.u_test,
                                                       model.dx))
    J = ufl.derivative(R, U, model.u_trial)
    with Timer() as t:
        Rf, Jf = fem.form(R), fem.form(J)
    out["compile_first_s"] = t.s
    with Timer() as t:
        fem.form(R), fem.form(J)
    out["compile_warm_s"] = t.s
    with Timer() as t:
        F = model.rotating_load()
    out["loads_s"] = t.s
    U.x.array[:] = 1e-4 * np.random.default_rng(0).standard_normal(U.x.array.size)
    b, A = create_vector(Rf), create_matrix(Jf)
    with Timer() as t:
        for _ in range(repeats):
            with b.localForm() as bl:
                bl.set(0.0)
            assemble_vector(b, Rf)
    out["residual_assembly_s"] = t.s / repeats
    with Timer() as t:
        for _ in range(repeats):
            A.zeroEntries()
            assemble_matrix(A, Jf, bcs=[model.bc])
            A.assemble()
    out["jacobian_assembly_s"] = t.s / repeats
    ksp = direct_solver(A)
    x = b.duplicate()
    with Timer() as t:
        ksp.setUp()
    out["factorisation_s"] = t.s
    with Timer() as t:
        ksp.solve(F, x)
    out["triangular_solve_s"] = t.s
    ksp.destroy()
    newton = []
    for rpm in PAPER_RPM:
        with Timer() as t:
            st = tlf_steady(model, rpm * 2 * np.pi / 60)
        newton.append({"rpm": rpm, "newton_s": t.s, "iterations": st.iterations,
                       "stages": st.extra.get("continuation_stages", 1),
                       "converged": st.converged, "tip_mm": (1e3 * st.tip).tolist()})
    out["newton"] = newton
    return out


def run(scene: Scene, out_dir: str, comm, quick: bool = False) -> dict:
    if comm.size != 1:
        raise FxflexError("bench steady: run it on one process; it starts its own mpirun -n 2")
    if quick:
        scene = scene.replace(**{"mesh.solid": (20, 4, 2)})
    comp = components(scene, comm)
    processes = []
    for ranks in (1, 2):
        for rpm in PAPER_RPM:
            r = run_cli(["steady", "--method", "tlf", "--rpm", repr(rpm)], scene, ranks)
            row = {"ranks": ranks, "rpm": rpm, "wall_s": r["wall_s"]}
            if "error" in r:
                row["error"] = r["error"]
            else:
                row.update(preprocess_s=r["timings_s"]["preprocess"],
                           solve_s=r["timings_s"]["solve"], iterations=r["iterations"],
                           tip_mm=r["tip_mm"])
            processes.append(row)
    info = machine()
    md = [f"# TLF steady state: time breakdown\n\nMesh {list(scene.mesh.solid)} "
          f"({3 * np.prod(scene.mesh.solid)} cells x 3), {info['cpu']}, {info['cores']} cores, "
          f"{info['date']}. Command: `fxflex bench steady`.\n",
          "## Components (serial, in process)\n",
          markdown_table(["piece", "seconds"], [[k, v] for k, v in comp.items()
                                               if k != "newton"]),
          "\n## Newton (serial, in process)\n",
          markdown_table(["rpm", "Newton s", "iterations", "stages", "converged"],
                         [[n["rpm"], n["newton_s"], n["iterations"], n["stages"], n["converged"]]
                          for n in comp["newton"]]),
          "\n## `fxflex steady --method tlf` as a process\n",
          markdown_table(["ranks", "rpm", "process wall s", "preprocess s", "solve s",
                          "iterations"],
                         [[p["ranks"], p["rpm"], p["wall_s"], p.get("preprocess_s", "-"),
                           p.get("solve_s", p.get("error", "-")), p.get("iterations", "-")]
                          for p in processes])]
    text = "\n".join(md)
    with open(os.path.join(out_dir, "steady.md"), "w") as fh:
        fh.write(text)
    with open(os.path.join(out_dir, "steady.json"), "w") as fh:
        json.dump({"machine": info, "components": comp, "processes": processes}, fh, indent=1)
    worst = max(n["newton_s"] for n in comp["newton"])
    summary = (f"bench steady: slowest Newton solve {worst:.2f} s serial (target < 10 s); "
               f"tables in {out_dir}/steady.md")
    return {"summary": summary, "machine": info, "components": comp, "processes": processes}
