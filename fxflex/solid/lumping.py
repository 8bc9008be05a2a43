"""HRZ lumping (Hinton, Rock and Zienkiewicz 1976) of the solid's mass, Eq. 29.

The row sums of the consistent mass of a 10-node tetrahedron are rho V_e / 5 at the mid-edge nodes
and -rho V_e / 20 at the vertices (int N dV of the quadratic Lagrange functions): central
differences cannot divide by them. HRZ keeps the consistent diagonal's
proportions and scales them to the element's mass, per direction,

    m_i^e = M_ii^e m_e / sum_j M_jj^e,   M_ii^e = int_e rho N_i^2 dV > 0,   m_e = int_e rho dV,

and sums the element contributions at the shared nodes: every entry is positive on any valid
cell, and the total is the body's mass (rho times the volume of the mesh, both to the
quadrature's accuracy). On an affine 10-node tetrahedron M_ii^e = rho V_e / 70 (vertex) and
8 rho V_e / 105 (edge), so HRZ puts 1 / 36 of m_e on each vertex and 4 / 27 on each edge node.
On the 4-node tetrahedron HRZ and the row sums are the same m_e / 4.

The element diagonals M_ii^e are the diagonal of the consistent mass on the discontinuous
Lagrange space of the same degree (block-diagonal: one block per cell, dofs in the cell's local
order, which for degree <= 2 is the continuous space's); the cell masses m_e the DG0 vector
int rho v. Both assembled with the model's quadrature; the scaling and the sum over cells run in
numpy on the owned cells, the ghost nodes' shares sent to their owners.
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem, la

__all__ = ["hrz_lumped_mass"]


def hrz_lumped_mass(model) -> np.ndarray:
    """The HRZ-lumped mass of a :class:`~fxflex.solid.model.SolidModel` (module docstring): its
    owned entries, 3 per node (the same value in X, Y, Z). Collective on ``model.comm``."""
    from dolfinx.fem.petsc import assemble_matrix, assemble_vector

    mesh, rho, dx = model.mesh, model.rho, model.dx
    cells = mesh.topology.index_map(mesh.topology.dim).size_local
    W = fem.FunctionSpace(mesh, ("DG", model.degree))
    u, v = ufl.TrialFunction(W), ufl.TestFunction(W)
    M = assemble_matrix(fem.form(rho * u * v * dx))
    M.assemble()
    diagonal = M.getDiagonal().getArray().copy()         # owned DG dofs: the owned cells'
    M.destroy()
    W0 = fem.FunctionSpace(mesh, ("DG", 0))
    m_cell = assemble_vector(fem.form(rho * ufl.TestFunction(W0) * dx)).getArray()
    dg = W.dofmap.list.array.reshape(-1, W.dofmap.dof_layout.num_dofs)[:cells]
    cg = model.V.dofmap.list.array.reshape(-1, model.V.dofmap.dof_layout.num_dofs)[:cells]
    dg0 = W0.dofmap.list.array[:cells]
    d = diagonal[dg]                                       # (cells, dofs per cell)
    share = d * (m_cell[dg0] / d.sum(axis=1))[:, None]
    out = fem.Function(model.V)
    nodes = np.zeros(out.x.array.size // 3)
    np.add.at(nodes, cg.ravel(), share.ravel())
    out.x.array[:] = np.repeat(nodes, 3)
    out.x.scatter_reverse(la.ScatterMode.add)
    return out.x.array[: model.n_owned].copy()
