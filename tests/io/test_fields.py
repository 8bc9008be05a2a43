"""io.fields: the one XDMF writer writes what the formulation's displacement callable returns,
as ``u`` and ``U_hub``, at every call (rank-collective, the same path on every rank)."""

import pathlib

import numpy as np
from dolfinx import fem, mesh
from mpi4py import MPI

from fxflex.io.fields import FieldWriter

COMM = MPI.COMM_WORLD


def test_writer_writes_the_callables_fields_every_call(tmp_path):
    domain = mesh.create_unit_cube(COMM, 2, 2, 2)
    V = fem.VectorFunctionSpace(domain, ("Lagrange", 1))
    n = 3 * V.dofmap.index_map.size_local
    seen = []

    def displacement(t, q):
        seen.append(t)
        return q, 2.0 * q + t

    path = pathlib.Path(COMM.bcast(str(tmp_path), root=0)) / "f.xdmf"
    writer = FieldWriter(COMM, V, str(path), displacement)
    q = np.linspace(0.0, 1.0, n)
    for t in (0.0, 0.5, 1.0):
        writer.write(t, q)
    writer.close()
    assert seen == [0.0, 0.5, 1.0]
    assert np.array_equal(writer.u.x.array[:n], q)
    assert np.array_equal(writer.U.x.array[:n], 2.0 * q + 1.0)
    text = path.read_text()
    assert text.count('Attribute Name="u"') == 3 and text.count('Attribute Name="U_hub"') == 3
    assert path.with_suffix(".h5").exists()
