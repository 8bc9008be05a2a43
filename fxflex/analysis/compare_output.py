"""The files of ``fxflex compare`` (:mod:`fxflex.analysis.compare`): the CSV tables, results.json,
paper.csv and report.md, written by rank 0 into the output folder."""

from __future__ import annotations

import csv
import json
import math
import os

from fxflex.analysis.compare_report import how
from fxflex.io.payload import COMPONENTS, jsonable

__all__ = ["write_csv", "write_results", "cell", "transient_row"]


def write_csv(path: str, rows: list[dict]) -> None:
    """``rows`` as a CSV table, the columns in order of first appearance."""
    keys = list(rows[0])
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        for r in rows:
            w.writerow({k: cell(r.get(k)) for k in keys})


def write_results(out_dir: str, result: dict, report: str) -> None:
    """results.json, paper.csv (the SPEC section 7 rows with how each is compared) and
    report.md."""
    with open(os.path.join(out_dir, "results.json"), "w") as fh:
        json.dump(jsonable(result), fh, indent=1)
    if result["paper"]:
        write_csv(os.path.join(out_dir, "paper.csv"),
                  [{**f, "how": how(f)} for f in result["paper"]])
    with open(os.path.join(out_dir, "report.md"), "w") as fh:
        fh.write(report)


def cell(x):
    """A CSV cell: floats at 10 digits (empty when not finite), lists space-separated."""
    if isinstance(x, float):
        return f"{x:.10g}" if math.isfinite(x) else ""
    if isinstance(x, (list, tuple)):
        return " ".join(cell(v) for v in x)
    return "" if x is None else x


def transient_row(study: str, s: dict) -> dict:
    """One row of transients.csv: a run's case and summary flattened to columns."""
    c = s["case"]
    row = {"study": study, **{k: c[k] for k in ("method", "rpm", "c", "model", "integrator",
                                                "dt", "t_end", "mass")}}
    for k in ("final_mm", "hann_mean_mm", "steady_mm", "peak_mm"):
        v = s.get(k)
        for comp, x in zip(COMPONENTS, v or (None, None, None)):
            row[f"{k[:-3]}_{comp}_mm"] = x
    d = s["diverged"]
    row.update(diverged_s=d["time_s"] if d else None, cause=d["cause"] if d else None,
               measured_growth=s["measured_growth"], eigen_growth=s["eigen_growth"],
               vs_half=s.get("vs_half"), sigma_root_max_MPa=s.get("sigma_root_max_MPa"),
               sigma_root_min_MPa=s.get("sigma_root_min_MPa"),
               torque_mean_Nm=s.get("torque_mean_Nm"), torque_peak_Nm=s.get("torque_peak_Nm"),
               steps=s["steps"], wall_s=s["wall_s"], us_per_step=s["us_per_step"])
    return row
