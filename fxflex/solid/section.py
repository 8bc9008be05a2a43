"""Stress resultants of the root section of the solid, from the UFL stress in the root cells.

The internal force on the clamped root nodes, Q_i = int sigma : grad(N_i) dV over the cells that
touch the root face (the stress integrated against the root nodes' shape functions), is the force
that the beam's stress transmits to the clamp: in equilibrium it is exactly the support reaction,
whatever the mesh. Its resultants about the root centre (node coordinates Y_i, Z_i of the
undeformed section) give the section forces of beam theory,

    N = -sum_i Q_X,i,   int Y sigma_X dA = -sum_i Y_i Q_X,i,   int Z sigma_X dA = -sum_i Z_i Q_X,i

(a bar in tension pulls the clamp along -X: Q_X < 0 there), from which
:meth:`fxflex.mesh.geometry.BeamShape.axial_stress` spreads sigma_X over the section corners as the
beam methods do. The pointwise Q1 stress at the clamped face is not used: the clamp also holds the
lateral strain there, which raises sigma_XX to (lambda + 2 mu) eps_XX (1.26 times beam theory on a
uniform cantilever, 100 x 12 x 6 mesh).

Stress laws: ``hooke`` (FFRF, GCMS: the linear strain of Eq. 12-14) on a displacement in O-XYZ,
``svk`` (TLF: the first Piola-Kirchhoff stress F S of Eq. 30-33) on the hub-frame displacement
U = A^T (x0 + u) - x0.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from dolfinx.fem.petsc import assemble_vector, create_vector
from petsc4py import PETSc

from fxflex.mesh.solid import ROOT
from fxflex.solid import forms

if TYPE_CHECKING:              # SolidModel.root_section builds this class: no import back
    from fxflex.solid.model import SolidModel

__all__ = ["RootSection"]


class RootSection:
    """Root-section resultants (N, int Y sigma_X dA, int Z sigma_X dA) of a displacement field.

    Collective on ``model.comm``: every rank calls :meth:`resultants` with its owned entries.
    """

    def __init__(self, model: SolidModel, law: str = "hooke"):
        if law not in ("hooke", "svk"):
            raise ValueError(f"law: {law!r}; allowed: hooke svk")
        self.model = model
        mesh = model.mesh
        tdim = mesh.topology.dim
        ft = model.solid_mesh.facet_tags
        mesh.topology.create_connectivity(tdim - 1, tdim)
        cells = dmesh.compute_incident_entities(mesh, ft.indices[ft.values == ROOT], tdim - 1,
                                                tdim)
        cells = np.unique(cells).astype(np.int32)
        tags = dmesh.meshtags(mesh, tdim, cells, np.ones(cells.size, dtype=np.int32))
        dx = ufl.Measure("dx", domain=mesh, subdomain_data=tags, subdomain_id=1,
                         metadata={"quadrature_degree": model.quadrature_degree})
        self.U = fem.Function(model.V)
        v, mat = model.u_test, model.scene.material
        if law == "hooke":
            L = ufl.inner(forms.hooke(mat, forms.epsilon(self.U)), ufl.grad(v)) * dx
        else:
            L = forms.svk_residual(mat, self.U, v, dx)
        self.form = fem.form(L)
        self.vec = create_vector(self.form)
        x0 = model.node_coordinates()[model.root_owned]
        self.rows = 3 * model.root_owned                 # X entries of the owned root nodes
        self.Y, self.Z = x0[:, 1], x0[:, 2]
        self.n = model.n_owned

    def resultants(self, U: np.ndarray) -> np.ndarray:
        """(N, int Y sigma_X dA, int Z sigma_X dA) for this rank's owned displacements U (O-XYZ);
        the same on every rank."""
        self.U.x.array[: self.n] = U
        self.U.x.scatter_forward()
        with self.vec.localForm() as loc:
            loc.set(0.0)
        assemble_vector(self.vec, self.form)
        self.vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        qx = self.vec.getArray(readonly=True)[self.rows]
        local = -np.array([qx.sum(), self.Y @ qx, self.Z @ qx])
        return self.model.comm.allreduce(local)

    def resultant_matrix(self, basis: np.ndarray) -> np.ndarray:
        """(3, k): the resultants of each column of an owned-row basis (n_owned, k); the Hooke
        law is linear, so the resultants of basis @ z are this matrix times z."""
        return np.column_stack([self.resultants(basis[:, j]) for j in range(basis.shape[1])])
