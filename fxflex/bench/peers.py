"""fxflex bench pybmodes (issue 16): fxflex's beams beside pyBModes on a uniform rotating
cantilever (docs/pybmodes.md).

pyBModes (PyPI ``pybmodes``, the Python successor of NREL's BModes) is a peer code, installed by
``./dev`` (``pip --no-deps``; it is not a dependency of fxflex). The cantilever is the scene's
root section (the paper's rectangle), untwisted and untapered, with the scene's material, hub
radius and length, and a second one three times as long at the same tip speeds (rpm / 3), where
rotary inertia matters nine times less. Per case and speed: the lowest modes of LEBB, NEBB and
ANCF (``fxflex modes`` without line load and damping; 40 elements per scene length, which is
converged to about 5e-5 against the gaps of 1e-4 and more discussed) and of pyBModes on as many
elements, matched by family (out-of-plane = flap, in-plane = edge, torsion) and ordinal, and the
relative gap. pyBModes' input is written to ``out_dir/inputs`` (a .bmi and its section table),
so every row can be rerun by hand. The section goes to pyBModes with ``section.torsion =
"polar"`` (G (I_y + I_z), the paper's torsion constant) on both sides.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

from fxflex.bench.common import machine, markdown_table
from fxflex.errors import FxflexError
from fxflex.scene import Scene

__all__ = ["run", "uniform_scene", "section_row", "pybmodes_frequencies", "SPEEDS"]

#: hub speeds (rpm) of the scene-length cantilever; the long one runs at a third of each
SPEEDS = (0.0, 1000.0, 5000.0, 10000.0)
METHODS = ("lebb", "nebb", "ancf")
FAMILIES = {"out-of-plane": "flap", "in-plane": "edge", "torsion": "torsion"}
#: elements per scene length, on both sides
ELEMENTS = 40
MODES = 8


def _pybmodes():
    try:
        from pybmodes.models import RotatingBlade
    except ImportError:
        raise FxflexError("bench pybmodes: needs pyBModes, a peer code fxflex does not depend on; "
                          "allowed: install it into the venv (./dev setup does, or .venv/bin/pip "
                          "install --no-deps pybmodes==1.19.1)") from None
    return RotatingBlade


def uniform_scene(scene: Scene, length: float, rpm: float, elements: int) -> Scene:
    """The uniform cantilever: the scene's root rectangle along ``length``, no twist, taper,
    load, damping or tip mass, polar torsion constant."""
    g = scene.geometry
    if g.section != "rectangle" or g.stations or g.wall or scene.mesh.solid_file:
        raise FxflexError("bench pybmodes: the cantilever is built from the paper's rectangle; "
                          "allowed: geometry.section = rectangle without stations or wall")
    return scene.replace(**{"geometry.twist_deg": 0.0, "geometry.tip_y": g.root_y,
                            "geometry.tip_z": g.root_z, "geometry.length": length,
                            "load.line_load": 0.0, "load.tip_force": [0.0, 0.0, 0.0],
                            "damping.c": 0.0, "rotation.rpm": rpm, "rotation.profile": "constant",
                            "mesh.beam_elements": elements, "section.torsion": "polar",
                            "tip_mass.mass": 0.0, "tip_mass.inertia": [0.0, 0.0, 0.0]})


def section_row(scene: Scene) -> dict:
    """pyBModes' section properties of the root rectangle (b along Y in the plane of rotation,
    h along Z): flap = bending out of the plane (about Y), edge = in the plane (about Z)."""
    g, m = scene.geometry, scene.material
    b, h = g.root_y, g.root_z
    A, Iy, Iz = b * h, b * h ** 3 / 12.0, h * b ** 3 / 12.0
    G = m.E / (2.0 * (1.0 + m.nu))
    return {"mass_den": m.rho * A, "flp_iner": m.rho * Iy, "edge_iner": m.rho * Iz,
            "flp_stff": m.E * Iy, "edge_stff": m.E * Iz, "tor_stff": G * (Iy + Iz),
            "axial_stff": m.E * A}


_BMI = """==========================   Main Input File   ==========================
fxflex bench pybmodes: uniform rotating cantilever

--------- General parameters ---------------------------------------------------------------------
false     Echo        Echo input file contents to *.echo file if true.
1         beam_type   1: blade, 2: tower (-)
{rpm:.10g}    rot_rpm:    rotor speed (rpm)
1.0       rpm_mult:   rotor speed multiplicative factor (-)
{radius:.10g}    radius:     blade tip radius measured along blade axis (m)
{hub:.10g}    hub_rad:    hub radius (m)
0.        precone:    built-in precone angle (deg)
0.        bl_thp:     blade pitch setting (deg)
1         hub_conn:   1 = cantilevered root
{modes}        modepr:     number of modes to be printed (-)
t         TabDelim    (true: tab-delimited output tables)
f         mid_node_tw  (false: no mid-node twist outputs)

--------- Blade-tip or tower-top mass properties --------------------------------------------
0.        tip_mass    blade-tip mass (kg)
0.        cm_loc      tip-mass c.m. transverse offset (m)
0.        cm_axial    tip-mass c.m. axial offset (m)
0.        ixx_tip     (kg-m^2)
0.        iyy_tip     (kg-m^2)
0.        izz_tip     (kg-m^2)
0.        ixy_tip     (kg-m^2)
0.        izx_tip     (kg-m^2)
0.        iyz_tip     (kg-m^2)

--------- Distributed-property identifiers --------------------------------------------------------
1         id_mat:     material_type [1: isotropic]
'{sec}' sec_props_file   name of beam section properties file (-)

Property scaling factors..............................
1.0       sec_mass_mult:   mass density multiplier (-)
1.0       flp_iner_mult:   blade flap inertia multiplier (-)
1.0       lag_iner_mult:   blade lag inertia multiplier (-)
1.0       flp_stff_mult:   blade flap bending stiffness multiplier (-)
1.0       edge_stff_mult:  blade lag bending stiffness multiplier (-)
1.0       tor_stff_mult:   torsion stiffness multiplier (-)
1.0       axial_stff_mult: axial stiffness multiplier (-)
1.0       cg_offst_mult:   cg offset multiplier (-)
1.0       sc_offst_mult:   shear center multiplier (-)
1.0       tc_offst_mult:   tension center multiplier (-)

--------- Finite element discretization --------------------------------------------------
{n}        nselt:     number of beam elements (-)
Distance of element boundary nodes from blade root (normalized wrt blade length), el_loc()
{locs}

END of Main Input File Data *********************************************************************
"""

_SEC_HEADER = """fxflex bench pybmodes: uniform section
2         n_secs:     number of stations at which properties are specified (-)

sec_loc  str_tw  tw_iner   mass_den  flp_iner  edge_iner  flp_stff   edge_stff   tor_stff   axial_stff  cg_offst  sc_offst tc_offst
(-)      (deg)   (deg)     (kg/m)    (kg-m)    (kg-m)     (Nm^2)     (Nm^2)      (Nm^2)     (N)         (m)       (m)      (m)
"""


def write_inputs(scene: Scene, folder: str, stem: str) -> str:
    """pyBModes' .bmi and section table for the uniform ``scene``; the .bmi path."""
    row = section_row(scene)
    values = " ".join(f"{row[k]:.10e}" for k in ("mass_den", "flp_iner", "edge_iner", "flp_stff",
                                                 "edge_stff", "tor_stff", "axial_stff"))
    sec = f"{stem}_sec.dat"
    with open(os.path.join(folder, sec), "w") as fh:
        fh.write(_SEC_HEADER + "".join(f"{x:.1f} 0.0 0.0 {values} 0.0 0.0 0.0\n"
                                       for x in (0.0, 1.0)))
    g, n = scene.geometry, scene.mesh.beam_elements
    path = os.path.join(folder, f"{stem}.bmi")
    with open(path, "w") as fh:
        fh.write(_BMI.format(rpm=scene.rotation.rpm, radius=g.hub_radius + g.length,
                             hub=g.hub_radius, modes=MODES, sec=sec, n=n,
                             locs=" ".join(f"{x:.10g}" for x in np.linspace(0.0, 1.0, n + 1))))
    return path


def pybmodes_frequencies(path: str, elements: int, row: dict) -> list[tuple[str, float]]:
    """(family, Hz) of pyBModes' lowest modes, lowest first; the family is the largest share of
    the mode's kinetic energy on the uniform section ``row`` (:func:`section_row`): rho A w^2
    (flap), rho A v^2 (edge), rho I_p phi^2 (torsion), summed over its nodes."""
    import warnings

    blade_cls = _pybmodes()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # its model checks warn on a uniform deck
        res = blade_cls(path, n_nodes=elements + 1).run(n_modes=MODES, on_error="warn")
    names = ("flap", "edge", "torsion")
    polar = row["flp_iner"] + row["edge_iner"]
    energies = np.array([[row["mass_den"] * np.sum(np.square(shape.flap_disp)),
                          row["mass_den"] * np.sum(np.square(shape.lag_disp)),
                          polar * np.sum(np.square(shape.twist))] for shape in res.shapes])
    # its shapes carry no axial displacement: an axial mode has none of the three (round-off,
    # 1e-19 of the others' 1e-2 on mass-normalised shapes)
    axial = energies.sum(axis=1) < 1e-12 * np.median(energies.sum(axis=1))
    return [("axial" if a else names[int(np.argmax(e))], float(f))
            for f, e, a in zip(res.frequencies, energies, axial)]


def _ordinals(pairs) -> dict[tuple[str, int], float]:
    """{(family, ordinal): Hz}, ordinals 1, 2, ... by frequency within each family."""
    out, count = {}, {}
    for family, hz in sorted(pairs, key=lambda p: p[1]):
        count[family] = count.get(family, 0) + 1
        out[(family, count[family])] = hz
    return out


def fxflex_frequencies(method: str, scene: Scene) -> list[tuple[str, float]]:
    from fxflex import api

    m = api.modes(api.build(method, scene), n=MODES)
    return [(FAMILIES.get(label, label), float(f))
            for label, f in zip(m.labels, m.frequencies_hz)]


def run(scene: Scene, out_dir: str, comm, quick: bool = False) -> dict:
    """Both cantilevers at every speed (quick: the scene-length one at 0 and 1000 rpm); JSON
    written after each row's speed."""
    _pybmodes()
    inputs = os.path.join(out_dir, "inputs")
    if comm.rank == 0:
        os.makedirs(inputs, exist_ok=True)
    comm.barrier()
    L = scene.geometry.length
    cases = [(1.0, SPEEDS[:2] if quick else SPEEDS)] + ([] if quick else [(3.0, SPEEDS)])
    info = {"machine": machine(), "ranks": comm.size, "quick": quick, "elements_per_length":
            ELEMENTS, "section": section_row(uniform_scene(scene, L, 0.0, ELEMENTS))}
    rows, t0 = [], time.perf_counter()
    for scale, speeds in cases:
        for rpm0 in speeds:
            rpm, n = rpm0 / scale, int(round(ELEMENTS * scale))
            case = uniform_scene(scene, scale * L, rpm, n)
            stem = f"L{scale * L:g}_rpm{rpm:g}"
            peer = {}
            if comm.rank == 0:
                peer = _ordinals(pybmodes_frequencies(write_inputs(case, inputs, stem), n,
                                                       section_row(case)))
            peer = comm.bcast(peer)
            ours = {m: _ordinals(fxflex_frequencies(m, case)) for m in METHODS}
            for key in sorted(peer, key=peer.get):
                row = {"length_m": scale * L, "rpm": rpm, "family": key[0], "ordinal": key[1],
                       "pybmodes_hz": peer[key]}
                for m in METHODS:
                    hz = ours[m].get(key)
                    row[f"{m}_hz"] = hz
                    row[f"{m}_gap"] = hz / peer[key] - 1.0 if hz is not None else None
                rows.append(row)
            if comm.rank == 0:
                with open(os.path.join(out_dir, "pybmodes.json"), "w") as fh:
                    json.dump({"info": info, "rows": rows}, fh, indent=1)
    info["wall_s"] = time.perf_counter() - t0
    text = render(rows, info)
    if comm.rank == 0:
        with open(os.path.join(out_dir, "pybmodes.json"), "w") as fh:
            json.dump({"info": info, "rows": rows}, fh, indent=1)
        with open(os.path.join(out_dir, "pybmodes.md"), "w") as fh:
            fh.write(text)
    comm.barrier()
    return {"summary": text + f"\n(tables in {out_dir}/pybmodes.md)", "info": info, "rows": rows}


def render(rows: list[dict], info: dict) -> str:
    head = ["L m", "rpm", "mode", "pyBModes Hz"] + [f"{m} Hz (gap)" for m in METHODS]

    def cell(r, m):
        hz = r[f"{m}_hz"]
        return "-" if hz is None else f"{hz:.4f} ({r[f'{m}_gap']:+.2e})"

    body = [[f"{r['length_m']:g}", f"{r['rpm']:g}", f"{r['family']} {r['ordinal']}",
             f"{r['pybmodes_hz']:.4f}"] + [cell(r, m) for m in METHODS] for r in rows]
    return ("bench pybmodes: uniform rotating cantilever, fxflex beams beside pyBModes "
            f"({info['elements_per_length']} elements per scene length on both sides)\n\n"
            + markdown_table(head, body) + "\n")
