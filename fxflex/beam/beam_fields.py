"""Field output (``--fields``) of the beam methods: the beam as a line mesh for ParaView.

The mesh is the undeformed centerline, one interval cell per beam element and one vertex per node
at X0 = (R + x, 0, 0) in O-XYZ (R the hub radius, x in [0, L] from the root), a dolfinx mesh of
dimension 1 in 3-D on COMM_SELF. On it, three P1 vector fields at each ``write(t, q)``, written by
:class:`fxflex.io.fields.FieldWriter` (so named and ordered as the solids' ``u`` and ``U_hub``):

- ``U_hub``: the centerline displacement in the hub frame O-XYZ, relative to the rigidly rotated
  undeformed beam (SPEC section 2): its tip node is the reported tip deflection;
- ``u``: the same displacement in the inertial frame o-xyz, u = A (X0 + U) - X0, as the solids
  write it (X0 + u is where the node is; warp the mesh by u to see the beam turn);
- ``rotation``: the section's rotation vector about X, Y, Z (rad, O-XYZ, relative to the
  undeformed section). LEBB and NEBB: the nodal theta_X, theta_Y, theta_Z they carry (Eq. 36-37,
  small rotations: theta_Y = -W_Z', theta_Z = W_Y'). ANCF: the rotation vector (axis times
  angle) of the rotation R of the polar decomposition F = R S of the node's gradient map
  F = D D0^-1, where the columns of D are the axial and the two section gradients dr/dX~,
  dr/dY~, dr/dZ~ turned to O-XYZ (A^T d) and D0 the same in the reference configuration e0:
  the closest rotation to F, exact for any rotation size, and equal to the small-rotation
  theta of ``ANCF.mode_tip`` to first order.

Beams are replicated on every rank (``form.comm`` is COMM_SELF): rank 0 of the communicator the
run shares (COMM_WORLD unless given) writes the file on COMM_SELF, the other ranks hold a writer
that does nothing, so ``fxflex run --fields`` under mpirun writes one file. dolfinx is imported
here only, when a writer is made: ``import fxflex`` and beam-only use stay free of it.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from fxflex.beam.line import BeamLine
from fxflex.scene.kinematics import rotation_z

__all__ = ["NodalFields", "line_field_writer", "frame_field_writer", "ancf_field_writer",
           "polar_rotation_vectors", "IdleWriter"]

#: (t, q) -> (u, U_hub, rotation), each (n_nodes, 3) in node order, root first
NodalFields = Callable[[float, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


class IdleWriter:
    """The field writer of the ranks that do not write: ``write`` and ``close`` do nothing."""

    def write(self, t: float, q: np.ndarray) -> None:
        """Nothing: rank 0 writes the replicated beam's fields."""

    def close(self) -> None:
        """Nothing to close."""


def line_mesh_space(line: BeamLine):
    """(V, order): the P1 vector space on the centerline mesh (COMM_SELF) and, for each of its
    nodes (blocks) in dof order, the beam node it sits on."""
    import ufl
    from dolfinx import fem, mesh
    from mpi4py import MPI

    x = np.zeros((line.n_nodes, 3))
    x[:, 0] = line.hub_radius + line.x_nodes
    cells = np.column_stack([np.arange(line.n_el), np.arange(1, line.n_nodes)]).astype(np.int64)
    cell = ufl.Cell("interval", geometric_dimension=3)
    domain = mesh.create_mesh(MPI.COMM_SELF, cells, x, ufl.Mesh(ufl.VectorElement("Lagrange",
                                                                                  cell, 1)))
    V = fem.VectorFunctionSpace(domain, ("Lagrange", 1))
    # dolfinx may renumber the nodes: find each dof node's beam node from its position
    xd = V.tabulate_dof_coordinates()[:, 0]
    order = np.rint((xd - line.hub_radius) / line.le).astype(int)
    if not np.array_equal(np.sort(order), np.arange(line.n_nodes)):    # pragma: no cover
        raise RuntimeError("the line mesh's nodes are not the beam's")
    return V, order


def line_field_writer(line: BeamLine, path: str, nodal: NodalFields, comm=None):
    """A writer of u, U_hub and rotation (``nodal``) on the beam line to the XDMF file ``path``
    from rank 0 of ``comm`` (default COMM_WORLD); an :class:`IdleWriter` on the other ranks."""
    from mpi4py import MPI

    if (comm or MPI.COMM_WORLD).rank != 0:
        return IdleWriter()
    from fxflex.io.fields import FieldWriter

    V, order = line_mesh_space(line)

    def fields(t: float, q: np.ndarray) -> tuple[np.ndarray, ...]:
        return tuple(np.ascontiguousarray(a[order]).reshape(-1) for a in nodal(t, q))

    return FieldWriter(MPI.COMM_SELF, V, path, fields, extra=("rotation",))


def frame_field_writer(form, path: str, comm=None):
    """``--fields`` of LEBB and NEBB (:class:`fxflex.beam.frame.FloatingFrameBeam`): W of every
    node (root clamped: zero) gives U_hub = (W_X, W_Y, W_Z), rotation = (theta_X, theta_Y,
    theta_Z), and u = A (X0 + U) - X0."""
    line, drive = form.line, form.drive
    X0 = np.zeros((line.n_nodes, 3))
    X0[:, 0] = line.hub_radius + line.x_nodes
    W = np.zeros((line.n_nodes, 6))

    def nodal(t: float, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        W[1:] = np.reshape(q, (-1, 6))
        U = W[:, :3]
        A = rotation_z(drive.angle(t))
        return (X0 + U) @ A.T - X0, U, W[:, 3:]

    return line_field_writer(line, path, nodal, comm)


def polar_rotation_vectors(F: np.ndarray) -> np.ndarray:
    """Rotation vectors (n, 3) of the rotations R of the polar decompositions F = R S of the
    (n, 3, 3) matrices F: R = P Q^T from the singular value decomposition F = P Sigma Q^T (the
    last column of P flipped where det(P Q^T) < 0, an inverted map), then axis times angle."""
    from scipy.spatial.transform import Rotation

    P, _, Qt = np.linalg.svd(F)
    flip = np.linalg.det(P @ Qt) < 0
    P[flip, :, -1] *= -1
    return Rotation.from_matrix(P @ Qt).as_rotvec()


def ancf_field_writer(form, path: str, comm=None):
    """``--fields`` of ANCF (:class:`fxflex.beam.ancf.ANCF`): from the absolute nodal coordinates
    e (o-xyz), U_hub = A^T r - r0 (the tip as ``ANCF.tip``), u = r - r0 and the polar rotation of
    the node's gradients (module docstring)."""
    e0 = form.e0n                                        # (n_nodes, slots, 3)
    r0 = e0[:, 0]
    D0inv = np.linalg.inv(np.swapaxes(e0[:, 1:4], 1, 2))  # columns dr/dX~, dr/dY~, dr/dZ~
    drive = form.drive

    def nodal(t: float, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        e = np.reshape(q, e0.shape)
        A = rotation_z(drive.angle(t))
        r = e[:, 0]
        hub = e[:, 1:4] @ A                              # rows (A^T d)^T
        F = np.swapaxes(hub, 1, 2) @ D0inv
        return r - r0, r @ A - r0, polar_rotation_vectors(F)

    return line_field_writer(form.line, path, nodal, comm)
