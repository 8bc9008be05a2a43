"""What every benchmark needs: the machine, child runs of the CLI on N ranks, Markdown tables."""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time

# machine's old import path kept: it lives in fxflex.io.machine
from fxflex.io.machine import machine
from fxflex.scene import Scene

__all__ = ["machine", "scene_overrides", "child_env", "run_cli", "markdown_table", "Timer",
           "median_time", "REPEAT_BUDGET_S", "MAX_REPEATS"]


def scene_overrides(scene: Scene) -> list[str]:
    """``--set`` arguments that reproduce ``scene`` exactly in a child process."""
    out = []
    for sec, table in scene.to_dict().items():
        for key, value in table.items():
            out += ["--set", f"{sec}.{key}={json.dumps(value)}"]
    return out


def child_env() -> dict:
    """Environment for a child (mpirun) process: without the variables of this process's own
    MPI singleton, which would make the child believe it runs inside this job."""
    keep = ("OMPI_ALLOW_RUN_AS_ROOT", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM",
            "OMPI_MCA_rmaps_base_oversubscribe")
    env = {k: v for k, v in os.environ.items()
           if not (k.startswith(("OMPI_", "PMIX_", "PRTE_", "OPAL_")) and k not in keep)}
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    return env


def run_cli(args: list[str], scene: Scene, ranks: int = 1, timeout: float = 3600,
            env: dict | None = None) -> dict:
    """Run ``fxflex ARGS --json`` for ``scene`` on ``ranks`` ranks; its JSON plus ``wall_s``
    (whole process) or ``{"error": last stderr line}``. ``env``: extra environment variables
    (e.g. ``FXFLEX_CACHE``, ``FXFLEX_NO_CACHE``)."""
    cmd = [sys.executable, "-m", "fxflex", *args, "--json", *scene_overrides(scene)]
    if ranks > 1:
        cmd = ["mpirun", "-n", str(ranks), "--bind-to", "core"] + cmd
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env={**child_env(), **(env or {})},
                          timeout=timeout)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        return {"error": (proc.stderr.strip().splitlines() or ["no output"])[-1], "wall_s": wall}
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    out["wall_s"] = wall
    return out


def markdown_table(header: list[str], rows: list[list]) -> str:
    def cell(x):
        if isinstance(x, float):
            return f"{x:.4g}"
        return str(x)
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(x) for x in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


class Timer:
    """``with Timer() as t: ...; t.s`` -- elapsed seconds."""

    def __enter__(self):
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.s = time.perf_counter() - self.t0


#: :func:`median_time` repeats a call while its runs so far took less than this many seconds
REPEAT_BUDGET_S = 0.5
#: ... and at most this many times
MAX_REPEATS = 31


def median_time(fn, comm=None, budget: float = REPEAT_BUDGET_S, most: int = MAX_REPEATS
                ) -> tuple[object, float, int]:
    """(first result, median seconds, runs) of ``fn()``, run again while the runs so far took
    less than ``budget`` seconds in all (at most ``most`` runs). A millisecond route timed once
    varies by tens of per cent with the garbage collector and the caches' state (a beam
    ``--tol`` ladder: 3.1x one time, 2.7x the next against the same table route); a route of
    seconds runs once. ``comm``: the ranks agree on the count (each stops when the slowest
    rank's total reaches the budget), for a collective ``fn``; the median is this rank's."""
    times: list[float] = []
    while True:
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
        if len(times) == 1:
            first = result
        spent = sum(times)
        if comm is not None and comm.size > 1:
            from mpi4py import MPI
            spent = comm.allreduce(spent, op=MPI.MAX)
        if spent >= budget or len(times) >= most:
            break
    return first, statistics.median(times), len(times)
