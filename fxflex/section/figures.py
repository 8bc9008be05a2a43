"""PNG figures of ``fxflex section --plot`` (matplotlib, Agg backend; imported when drawing).

One figure per station: the section mesh, its centroid, shear centre and principal axes, in the
section's own coordinates (before the twist); and the blade: every station's outline placed at x,
centroid on the axis, twisted about it, in 3-D. Each file is written under a temporary name and
renamed, so a failure leaves no half-written PNG; a write that fails is one OutputError line.
"""

from __future__ import annotations

import math
import os

import numpy as np

from fxflex.errors import OutputError
from fxflex.section.blade import Blade
from fxflex.section.properties import RESOLUTION, triangles

__all__ = ["plot_sections"]


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _save(fig, path: str) -> None:
    tmp = f"{path}.part-{os.getpid()}.png"
    try:
        fig.savefig(tmp, dpi=110)
        os.replace(tmp, path)
    except OSError as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise OutputError(f"--plot: cannot write {path}: {exc.strerror or exc}") from None


def _section_figure(plt, blade: Blade, row: dict, resolution: int, path: str) -> None:
    outline = blade.outline(row["x"])
    pts, tri = triangles(outline, resolution)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.triplot(pts[:, 0], pts[:, 1], tri, lw=0.3, color="0.6")
    for c in outline.contours():
        closed = np.vstack([c, c[:1]])
        ax.plot(closed[:, 0], closed[:, 1], "k-", lw=1.0)
    yc, zc = row["centroid"]
    ys, zs = yc + row["shear_centre"][0], zc + row["shear_centre"][1]
    ax.plot(yc, zc, "o", color="C0", label="centroid")
    ax.plot(ys, zs, "x", color="C3", ms=9, mew=2, label="shear centre")
    th = math.radians(row["principal_deg"])
    for k, (dy, dz) in enumerate(((math.cos(th), math.sin(th)), (-math.sin(th), math.cos(th)))):
        ext = 0.6 * outline.extent[k]
        ax.plot([yc - ext * dy, yc + ext * dy], [zc - ext * dz, zc + ext * dz], "--",
                color="C2", lw=0.8, label="principal axes" if k == 0 else None)
    ax.set_aspect("equal")
    ax.set_xlabel("y (m)")
    ax.set_ylabel("z (m)")
    ax.set_title(f"x = {row['x']:.4g} m: A = {row['A']:.4g} m², J = {row['J']:.4g} m⁴, "
                 f"principal {row['principal_deg']:+.2f}°", fontsize=9)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def _blade_figure(plt, blade: Blade, rows: list[dict], path: str) -> None:
    fig = plt.figure(figsize=(8, 5))
    ax = fig.add_subplot(projection="3d")
    for row in rows:
        _, _, twist, _ = blade.sizes(row["x"])
        c, s = math.cos(twist), math.sin(twist)
        for k, contour in enumerate(blade.outline(row["x"]).contours()):
            local = np.vstack([contour, contour[:1]]) - row["centroid"]
            Y, Z = c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1]
            ax.plot(np.full(len(Y), row["x"]), Y, Z, color="C0" if k == 0 else "C1", lw=0.8)
    ax.set_xlabel("X (m)")
    ax.set_ylabel("Y (m)")
    ax.set_zlabel("Z (m)")
    ax.set_title(f"{len(rows)} stations, centroids on the X axis, twisted about it", fontsize=9)
    _save(fig, path)
    plt.close(fig)


def plot_sections(scene, rows: list[dict], folder: str, resolution: int | None = None,
                  enabled: bool = True) -> list[str]:
    """section_NN.png per station and blade.png into folder; the paths written."""
    if not enabled:
        return []
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"--plot: cannot create {folder}: {exc.strerror or exc}") from None
    plt = _pyplot()
    blade = Blade(scene.geometry)
    files = []
    for i, row in enumerate(rows):
        files.append(os.path.join(folder, f"section_{i:02d}.png"))
        _section_figure(plt, blade, row, resolution or RESOLUTION, files[-1])
    files.append(os.path.join(folder, "blade.png"))
    _blade_figure(plt, blade, rows, files[-1])
    return files
