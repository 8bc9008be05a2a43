"""Field output (``--fields``): the displacement on the mesh as an XDMF/HDF5 series for ParaView.

One writer for every formulation. What a formulation knows is how its state q becomes nodal
displacements; that is the callable it passes, ``displacement(t, q) -> (u, U)``, this rank's
owned entries of u in the inertial frame o-xyz and of U in the hub frame O-XYZ (U = A^T (x0 + u)
- x0 for TLF, the modal sum for FFRF and GCMS). The writer holds the file and the two named
functions, ``u`` and ``U_hub``, on the formulation's function space. A formulation with more to
show names further fields (``extra``, on the same space): its callable then returns them after
u and U, ``(u, U, *extra)`` (the beams' section rotation, :mod:`fxflex.beam.beam_fields`). It
imports no formulation, so :mod:`fxflex.io` stays below :mod:`fxflex.solid` and
:mod:`fxflex.beam`.

Q2 solids (``mesh.solid_degree = 2``): the space is P2 on the 27-node (order-2) geometry, and
dolfinx 0.5's XDMF writes a Lagrange field whose degree equals the geometry's as it is, on the
``Hexahedron_27`` topology, so the fields are written at every node (vertices, edge, face and
cell midpoints) with no interpolation to P1.

Reading back: :func:`read_dataset` loads one dataset of the HDF5 file (the mesh geometry,
``/Mesh/mesh/geometry``, or a snapshot named in the XDMF) through PETSc's HDF5 viewer, the build's
own HDF5, so no h5py is needed (dolfinx 0.5's XDMF reader knows no ``Hexahedron_27``).
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np
from dolfinx import fem

__all__ = ["Displacement", "FieldWriter", "read_dataset"]

#: (t, q) -> (u in o-xyz, U in O-XYZ, *extra fields), this rank's owned entries of the space
Displacement = Callable[[float, np.ndarray], tuple[np.ndarray, ...]]


class FieldWriter:
    """Writes u (name ``u``), U (name ``U_hub``) and the ``extra`` named fields, in that order, at
    each ``write(t, q)`` to one XDMF/HDF5 pair at ``path``. Collective on ``comm``: every rank
    opens the same path and calls ``write`` and ``close`` (the HDF5 writes are collective)."""

    def __init__(self, comm, V: fem.FunctionSpace, path: str, displacement: Displacement,
                 extra: Sequence[str] = ()):
        from dolfinx.io import XDMFFile

        self.displacement = displacement
        self.file = XDMFFile(comm, path, "w")
        self.file.write_mesh(V.mesh)
        self.u, self.U = fem.Function(V, name="u"), fem.Function(V, name="U_hub")
        self.functions = [self.u, self.U] + [fem.Function(V, name=name) for name in extra]

    def write(self, t: float, q: np.ndarray) -> None:
        values = self.displacement(t, q)
        if len(values) != len(self.functions):
            raise ValueError(f"the displacement callable returned {len(values)} arrays for the "
                             f"{len(self.functions)} fields "
                             f"{[f.name for f in self.functions]}")
        for f, x in zip(self.functions, values):
            f.x.array[: x.size] = x
        for f in self.functions:
            f.x.scatter_forward()
            self.file.write_function(f, t)

    def close(self) -> None:
        self.file.close()


def read_dataset(path, dataset: str, width: int = 3) -> np.ndarray:
    """One dataset of the fields' HDF5 file ``path`` as an (n, width) array, read on this
    process alone (module docstring)."""
    from mpi4py import MPI
    from petsc4py import PETSc

    viewer = PETSc.Viewer().createHDF5(str(path), "r", comm=MPI.COMM_SELF)
    vec = PETSc.Vec().create(comm=MPI.COMM_SELF)
    vec.setName(dataset)
    try:
        vec.load(viewer)
        return vec.getArray().reshape(-1, width).copy()
    finally:
        vec.destroy()
        viewer.destroy()
