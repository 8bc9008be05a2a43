"""mesh.solid_file (SPEC section 9): the user's gmsh .msh for FFRF, GCMS and TLF.

The built-in mesh of the default blade's rectangle, meshed as a polygon section (volume load q/A
and the tip face's area-weighted mean, as for any imported mesh), written by gmsh with physical
surfaces named "root" and "tip" and its root moved to X = 0, must reproduce the built-in mesh's
results to round-off; files that break the contract are refused with one line."""

import numpy as np
import pytest
from mpi4py import MPI

from fxflex.errors import FxflexError, SceneError
from fxflex.formulation import build
from fxflex.scene import Scene
from fxflex.scene.load import validate_for

COMM = MPI.COMM_WORLD
HUB = 0.2


def _polygon_scene(tmp, degree, divisions):
    g = Scene().geometry
    contour = tmp / "rect.csv"
    y, z = g.root_y / 2, g.root_z / 2
    if COMM.rank == 0:              # one writer: the folder is shared by the ranks
        contour.write_text("y,z\n" + "".join(f"{a},{b}\n" for a, b in
                                             ((-y, -z), (y, -z), (y, z), (-y, z))))
    COMM.barrier()
    return Scene().replace(**{"geometry.section": "polygon", "geometry.contour": str(contour),
                              "geometry.hub_radius": HUB, "mesh.solid": divisions,
                              "mesh.solid_degree": degree, "rotation.rpm": 5000.0})


def _export(scene, path, names=("root", "tip"), shift=True, volume_group=True):
    """The built-in mesh of ``scene`` rewritten as a user's file (rank 0)."""
    import gmsh

    from fxflex.mesh.solid import ROOT, TIP, build_solid_mesh
    sm = build_solid_mesh(scene.geometry, scene.mesh.solid, MPI.COMM_SELF,
                          order=scene.mesh.solid_degree)
    gmsh.initialize(readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        gmsh.open(str(sm.path))
        if shift:
            tags, xyz, _ = gmsh.model.mesh.getNodes()
            xyz = xyz.reshape(-1, 3)
            for tag, p in zip(tags, xyz):
                gmsh.model.mesh.setNode(int(tag), [p[0] - HUB, p[1], p[2]], [])
        surfaces = {tag: gmsh.model.getEntitiesForPhysicalGroup(2, tag) for tag in (ROOT, TIP)}
        volumes = [t for _, t in gmsh.model.getEntities(3)]
        gmsh.model.removePhysicalGroups()
        for name in ("root", "tip", "beam"):       # the names outlive their groups
            gmsh.model.removePhysicalName(name)
        if volume_group:
            gmsh.model.addPhysicalGroup(3, volumes, 7)
        for (tag, entities), name in zip(surfaces.items(), names):
            if name:
                gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, entities, 10 + tag),
                                           name)
        if not volume_group:                        # else gmsh writes no volume elements
            gmsh.option.setNumber("Mesh.SaveAll", 1)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("imported") if COMM.rank == 0 else None
    tmp = COMM.bcast(tmp, root=0)
    out = {}
    for degree, divisions in ((1, (8, 2, 2)), (2, (4, 2, 2))):
        scene = _polygon_scene(tmp, degree, divisions)
        path = tmp / f"blade-q{degree}.msh"
        if COMM.rank == 0:
            _export(scene, path)
        out[degree] = (scene, path)
    COMM.barrier()
    return out


def _imported(scene, path):
    return Scene().replace(**{"geometry.hub_radius": HUB, "mesh.solid_file": str(path),
                              "mesh.solid_degree": scene.mesh.solid_degree,
                              "rotation.rpm": scene.rotation.rpm})


@pytest.mark.parametrize("method,degree", [("tlf", 1), ("tlf", 2), ("ffrf", 2)])
def test_imported_mesh_reproduces_the_built_in_one(files, method, degree):
    scene, path = files[degree]
    if method == "ffrf":
        scene = scene.replace(**{"reduction.ffrf_modes": 6})
    ref = build(method, scene, COMM).steady_state().tip
    mine_scene = _imported(scene, path)
    if method == "ffrf":
        mine_scene = mine_scene.replace(**{"reduction.ffrf_modes": 6})
    form = build(method, mine_scene, COMM)
    tip = form.steady_state().tip
    # the same nodes, elements and loads: only the hub shift's round-off and the solvers'
    # tolerances (Newton 1e-10 relative for TLF) separate them
    assert np.linalg.norm(tip - ref) <= 1e-8 * np.linalg.norm(ref)
    assert form.dof == build(method, scene, COMM).dof


def _refused(scene, path, **kw):
    bad = path.with_name(f"bad-{len(kw)}-{'-'.join(map(str, kw.values()))}.msh")
    if COMM.rank == 0:
        _export(scene, bad, **kw)
    COMM.barrier()
    return bad


def test_bad_files_are_refused(files):
    scene, path = files[1]
    cases = [(dict(names=("root", "")), "no physical surface 'tip'"),
             (dict(shift=False), "spans X from 0.2")]
    for kw, message in cases:
        bad = _refused(scene, path, **kw)
        with pytest.raises(FxflexError, match=message):
            build("tlf", _imported(scene, bad), COMM)
    with pytest.raises(FxflexError, match="order 1 but mesh.solid_degree = 2"):
        build("tlf", _imported(scene, path).replace(**{"mesh.solid_degree": 2}), COMM)


def test_a_volume_group_is_not_needed(files):
    scene, path = files[1]
    bad = _refused(scene, path, volume_group=False)
    tip = build("tlf", _imported(scene, bad), COMM).steady_state().tip
    assert np.linalg.norm(tip) > 0


def test_scene_checks(files, tmp_path):
    scene, path = files[1]
    with pytest.raises(SceneError, match="mesh.solid_file.*not a file"):
        Scene().replace(**{"mesh.solid_file": str(tmp_path / "none.msh")})
    for method in ("lebb", "nebb", "ancf"):
        with pytest.raises(SceneError, match="beam method"):
            validate_for(method, _imported(scene, path))
