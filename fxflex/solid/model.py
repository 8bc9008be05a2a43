"""The solid discretisation shared by FFRF, GCMS and TLF.

Q1 hexahedra (paper Eq. 8) on the gmsh mesh, the root face clamped, quadrature degree set
explicitly (2 = 2x2x2 Gauss, exact for the linear part on affine cells; the paper used 3x3x3).
``degree=2`` gives isoparametric Q2 hexahedra (27-node geometry, 3x3x3 Gauss by default): the
scene key ``mesh.solid_degree`` (SPEC section 9) chooses it for FFRF, GCMS and TLF, and the
converged reference of :mod:`fxflex.analysis.reference` uses it at any scene degree.
Builds the loads of SPEC section 1 -- consistent nodal forces of the centerline line load and the
tip force as a uniform traction over the tip face -- and the tip probe (the tip section centre is a
mesh node that lives on one rank; its displacement is shared with allreduce). A section other than
the paper's rectangle (SPEC section 9) has no centerline nodes: the line load is a volume force
q / A(X) along z and the tip probe the area-weighted mean displacement of the tip face.
"""

from __future__ import annotations

import functools
import time

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from fxflex.errors import FxflexError
from fxflex.mesh.solid import ROOT, TIP, build_solid_mesh
from fxflex.scene import Scene
from fxflex.scene.kinematics import rotation_z
from fxflex.solid import forms

__all__ = ["SolidModel", "solid_dof_count"]


def solid_dof_count(scene: Scene, degree: int | None = None) -> int:
    """Nodal unknowns after the root clamp: 3 p nx (p ny + 1) (p nz + 1) for elements of degree
    p (``mesh.solid_degree`` unless given): 3 nx (ny + 1) (nz + 1) for the paper's Q1."""
    p = scene.mesh.solid_degree if degree is None else degree
    nx, ny, nz = scene.mesh.solid
    return 3 * p * nx * (p * ny + 1) * (p * nz + 1)


class SolidModel:
    """Mesh, function space, clamp, loads and tip probe of the solid beam."""

    def __init__(self, scene: Scene, comm, *, divisions=None, quadrature_degree: int | None = None,
                 degree: int | None = None):
        t0 = time.perf_counter()
        self.scene, self.comm = scene, comm
        self.divisions = tuple(divisions or scene.mesh.solid)
        degree = scene.mesh.solid_degree if degree is None else int(degree)
        self.degree = degree
        quadrature_degree = 2 * degree if quadrature_degree is None else quadrature_degree
        if scene.mesh.solid_file:
            from fxflex.mesh.imported import read_solid_file
            sm = read_solid_file(scene, comm)
        else:
            sm = build_solid_mesh(scene.geometry, self.divisions, comm, order=degree)
        # the paper's mesh: centerline nodes carry the line load and the tip probe (SPEC 1, 9)
        self.paper_mesh = scene.geometry.paper_shape and not scene.mesh.solid_file
        self.solid_mesh, self.mesh, self.shape = sm, sm.mesh, sm.shape
        self.timings = {"mesh": time.perf_counter() - t0}
        self.quadrature_degree = quadrature_degree
        md = {"quadrature_degree": quadrature_degree}
        self.dx = ufl.dx(domain=self.mesh, metadata=md)
        self.ds = ufl.Measure("ds", domain=self.mesh, subdomain_data=sm.facet_tags, metadata=md)
        self.V = fem.VectorFunctionSpace(self.mesh, ("Lagrange", degree))
        imap = self.V.dofmap.index_map
        self.n_owned_nodes = imap.size_local
        self.n_owned = 3 * imap.size_local          # length of a state array on this rank
        self.n_global_nodes = imap.size_global
        ft = sm.facet_tags
        root_facets = ft.indices[ft.values == ROOT]
        self.root_nodes = fem.locate_dofs_topological(self.V, 2, root_facets)
        self.bc = fem.dirichletbc(np.zeros(3, dtype=PETSc.ScalarType), self.root_nodes, self.V)
        owned_root = self.root_nodes[self.root_nodes < self.n_owned_nodes]
        self.root_owned = owned_root                 # owned block (node) indices on the root
        n_root = comm.allreduce(owned_root.size)
        self.dof = 3 * (self.n_global_nodes - n_root)
        self.X0 = ufl.SpatialCoordinate(self.mesh)
        self.u_test = ufl.TestFunction(self.V)
        self.u_trial = ufl.TrialFunction(self.V)
        self._locate_centerline()
        self.rho = scene.material.rho
        self._root_sections: dict = {}
        self._tip_face = None

    # -- geometry --------------------------------------------------------------------------------
    def _locate_centerline(self) -> None:
        g = self.scene.geometry
        if not self.paper_mesh:
            self._locate_tip_face()
            return
        tol = 1e-9 * g.length
        nodes = fem.locate_dofs_geometrical(
            self.V, lambda x: (np.abs(x[1]) < tol) & (np.abs(x[2]) < tol))
        nodes = nodes[nodes < self.n_owned_nodes]
        coords = self.V.tabulate_dof_coordinates()
        self.center_nodes = nodes
        self.center_x = coords[nodes, 0] - g.hub_radius   # distance from the root
        tip = nodes[np.abs(self.center_x - g.length) < tol]
        self.tip_node = int(tip[0]) if tip.size else None
        self.x0_tip = np.array([g.hub_radius + g.length, 0.0, 0.0])
        count = self.comm.allreduce(nodes.size)
        expected = self.degree * self.divisions[0] + 1
        if count != expected or self.comm.allreduce(tip.size) != 1:
            raise RuntimeError(f"centerline: found {count} nodes, expected {expected}")

    def _locate_tip_face(self) -> None:
        """Any other section (SPEC section 9): no centerline nodes; the tip probe is the tip
        centroid's displacement, taken as the area-weighted mean over the tip face, u_c =
        sum_i w_i u_i with w_i = int_tip N_i dA / A_tip (exact for a displacement linear over
        the face). ``tip_node`` is the tip node nearest the axis (for the sign of modes)."""
        g = self.scene.geometry
        self.center_nodes = np.zeros(0, dtype=np.int32)
        self.center_x = np.zeros(0)
        self.x0_tip = np.array([g.hub_radius + g.length, 0.0, 0.0])
        area = self.comm.allreduce(fem.assemble_scalar(fem.form(1.0 * self.ds(TIP))))
        w = self.vector(ufl.inner(fem.Constant(self.mesh, np.ones(3)), self.u_test)
                        * self.ds(TIP), zero_clamped=False)
        self.tip_weights = w.getArray()[: self.n_owned].reshape(-1, 3)[:, 0] / area
        ft = self.solid_mesh.facet_tags
        nodes = fem.locate_dofs_topological(self.V, 2, ft.indices[ft.values == TIP])
        nodes = nodes[nodes < self.n_owned_nodes]
        r = np.linalg.norm(self.V.tabulate_dof_coordinates()[nodes] - self.x0_tip, axis=1)
        best = (float(r.min()), self.comm.rank) if nodes.size else (np.inf, self.comm.rank)
        owner = self.comm.allreduce(best, op=MPI.MIN)[1]
        self.tip_node = int(nodes[np.argmin(r)]) if self.comm.rank == owner else None

    def node_coordinates(self) -> np.ndarray:
        """Undeformed coordinates X0 of the owned nodes, shape (n_owned_nodes, 3)."""
        return self.V.tabulate_dof_coordinates()[: self.n_owned_nodes].copy()

    # -- assembly ---------------------------------------------------------------------------------
    def compile(self, form):
        return fem.form(form)

    def matrix(self, a, *, bcs=None, diagonal: float = 1.0) -> PETSc.Mat:
        """Assemble a bilinear form; clamped rows/columns zero with ``diagonal`` on them."""
        from dolfinx.fem.petsc import assemble_matrix

        bcs = [self.bc] if bcs is None else bcs
        A = assemble_matrix(a if isinstance(a, fem.FormMetaClass) else fem.form(a), bcs=bcs,
                            diagonal=diagonal)
        A.assemble()
        return A

    def vector(self, L, *, zero_clamped: bool = True) -> PETSc.Vec:
        """Assemble a linear form into an owned+ghost PETSc vector (clamped entries zero)."""
        from dolfinx.fem.petsc import assemble_vector, set_bc

        b = assemble_vector(L if isinstance(L, fem.FormMetaClass) else fem.form(L))
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if zero_clamped:
            set_bc(b, [self.bc])
        return b

    def new_vector(self) -> PETSc.Vec:
        return fem.Function(self.V).vector.copy()

    # -- standard operators -----------------------------------------------------------------------
    def stiffness_form(self):
        return forms.linear_elastic(self.scene.material, self.u_trial, self.u_test, self.dx)

    def mass_form(self):
        return forms.mass(self.rho, self.u_trial, self.u_test, self.dx)

    def lumped_mass_form(self):
        """Row sums of the consistent mass (Eq. 29): int rho N_a, per component."""
        ones = fem.Constant(self.mesh, np.ones(3))
        return self.rho * ufl.inner(ones, self.u_test) * self.dx

    def lumped_mass(self) -> np.ndarray:
        """The owned entries of the lumped mass, checked positive: the row sums of the
        consistent mass, or HRZ (:mod:`fxflex.solid.lumping`) on 10-node tetrahedra, whose
        vertex row sums are negative (-rho V_e / 20).

        Q1 row sums are positive on any valid hexahedron. For the 27-node Q2 element they are the
        tensor products of the 1-D Simpson weights (1/6, 2/3, 1/6) h times rho |det J| on an affine
        cell, so positive as well, but a strongly curved cell could make one zero or negative;
        central differences would then divide by it, so that is refused (FxflexError) rather than
        run. Every user of a lumped mass (the explicit TLF, its w_max, the lumped linearisation of
        :mod:`fxflex.solid.rotating`) takes it from here."""
        if self.hrz_lumping:
            from fxflex.solid.lumping import hrz_lumped_mass
            m = hrz_lumped_mass(self)
        else:
            m = self.vector(self.lumped_mass_form(), zero_clamped=False).getArray()[: self.n_owned]
        low = self.comm.allreduce(float(m.min()) if m.size else np.inf, op=MPI.MIN)
        if not low > 0.0:
            how = "HRZ" if self.hrz_lumping else "row-sum"
            raise FxflexError(f"mesh.solid_degree = {self.degree}: the lumped ({how}) mass has "
                              f"an entry {low:.3g} <= 0 on mesh.solid {list(self.divisions)}; "
                              f"allowed: --mass consistent, or a finer mesh")
        return m.copy()

    @property
    def hrz_lumping(self) -> bool:
        """True where :meth:`lumped_mass` is HRZ's: quadratic tetrahedra (on linear ones HRZ is
        the row sum, m_e / 4 per vertex)."""
        return self.solid_mesh.kind == "tetrahedra" and self.degree == 2

    def mass_P_form(self):
        return forms.mass_P(self.rho, self.u_trial, self.u_test, self.dx)

    def mass_S_form(self):
        return forms.mass_S(self.rho, self.u_trial, self.u_test, self.dx)

    def centrifugal_form(self):
        return forms.centrifugal(self.rho, self.X0, self.u_test, self.dx)

    def euler_form(self):
        return forms.euler(self.rho, self.X0, self.u_test, self.dx)

    # -- loads ------------------------------------------------------------------------------------
    def line_load_vector(self) -> PETSc.Vec:
        """Consistent nodal forces of the centerline line load (full magnitude, along z).

        Along the centerline the shape functions restrict to the 1-D Lagrange functions of the
        element degree on each cell edge of length h = L / nx, so a uniform load q gives q times
        their integrals, the Newton-Cotes weights: Q1 q h at interior nodes and q h / 2 at the
        two ends; Q2 q h / 6 at each edge end (q h / 3 where two edges meet) and 2 q h / 3 at the
        midpoint.
        """
        if not self.paper_mesh:
            return self._volume_line_load()
        b = self.new_vector()
        L = self.scene.geometry.length
        h = L / self.divisions[0]
        p = self.degree
        weights = np.linalg.solve(np.vander(np.linspace(0.0, 1.0, p + 1), increasing=True).T,
                                  1.0 / np.arange(1, p + 2)) * h      # int_0^h l_i
        position = np.rint(self.center_x / h * p).astype(int)          # node index along the line
        local = position % p
        w = weights[local]
        w[(local == 0) & (position > 0) & (position < p * self.divisions[0])] *= 2.0
        with b.localForm() as bl:
            bl.set(0.0)
        arr = b.getArray()
        arr[3 * self.center_nodes + 2] = self.scene.load.line_load * w
        self._zero_clamped(b)
        return b

    def _volume_line_load(self) -> PETSc.Vec:
        """Any other section (SPEC section 9): the line load q as a uniform volume force
        q / A(X) along z, A(X) the mesh's section area (the root face's area times the stretch
        s_y s_z of :func:`fxflex.mesh.section_mesh.stretch`), so that its resultant per unit
        length is q on the centroid axis; 1 / A interpolated in the displacement space."""
        from fxflex.mesh.section_mesh import stretch

        area0 = self.comm.allreduce(fem.assemble_scalar(fem.form(1.0 * self.ds(ROOT))))
        R, q = self.scene.geometry.hub_radius, self.scene.load.line_load
        density = fem.Function(fem.FunctionSpace(self.mesh, ("Lagrange", self.degree)))

        def value(x):
            sy, sz, _ = stretch(self.shape, x[0] - R)
            return q / (area0 * sy * sz)

        density.interpolate(value)
        ez = fem.Constant(self.mesh, np.array([0.0, 0.0, 1.0]))
        return self.vector(density * ufl.inner(ez, self.u_test) * self.dx)

    def tip_traction_vectors(self) -> list[PETSc.Vec]:
        """Nodal forces of a unit force (1 N) along X, Y, Z spread uniformly over the tip face."""
        area = self.comm.allreduce(fem.assemble_scalar(fem.form(1.0 * self.ds(TIP))))
        out = []
        for i in range(3):
            e = np.zeros(3)
            e[i] = 1.0 / area
            out.append(self.vector(forms.traction(fem.Constant(self.mesh, e), self.u_test,
                                                  self.ds(TIP))))
        return out

    def _zero_clamped(self, b: PETSc.Vec) -> None:
        from dolfinx.fem.petsc import set_bc
        set_bc(b, [self.bc])

    def rotating_load(self) -> PETSc.Vec:
        """Full external load in O-XYZ after the ramp: line load + tip force (SPEC section 1)."""
        b = self.line_load_vector()
        f = np.asarray(self.scene.load.tip_force, float)
        if np.any(f):
            for fi, vec in zip(f, self.tip_traction_vectors()):
                b.axpy(fi, vec)
        return b

    def root_section(self, law: str = "hooke"):
        """The :class:`fxflex.solid.section.RootSection` of this mesh for a stress law, built once
        (collective on the first call)."""
        from fxflex.solid.section import RootSection

        if law not in self._root_sections:
            self._root_sections[law] = RootSection(self, law)
        return self._root_sections[law]

    # -- probe ------------------------------------------------------------------------------------
    def tip_displacement(self, array: np.ndarray) -> np.ndarray:
        """Displacement of the tip section centre from an owned-part array (3 per node), or (3, k)
        from an (n_owned, k) array; for a section other than the paper's, the tip centroid's
        (:meth:`_locate_tip_face`)."""
        if not self.paper_mesh:
            part = array[: self.n_owned].reshape((self.n_owned_nodes, 3) + array.shape[1:])
            return self.comm.allreduce(np.tensordot(self.tip_weights, part, axes=(0, 0)))
        local = np.zeros((3,) + array.shape[1:], dtype=array.dtype)
        if self.tip_node is not None:
            local[:] = array[3 * self.tip_node: 3 * self.tip_node + 3]
        return self.comm.allreduce(local)

    def tip_section(self, X: np.ndarray) -> np.ndarray:
        """(6, k): translation of the tip centre and small rotation of the tip section for each
        column of owned-entry arrays X (n_owned,) or (n_owned, k), real or complex (mode shapes).

        The rotation is the least-squares rigid fit over the tip face nodes about the centre c:
        theta = I^-1 sum_i r_i x (u_i - u_c), I = sum_i (|r_i|^2 1 - r_i r_i^T), r_i = X_i - c.
        Collective on ``comm``."""
        if self._tip_face is None:
            ft = self.solid_mesh.facet_tags
            nodes = fem.locate_dofs_topological(self.V, 2, ft.indices[ft.values == TIP])
            nodes = nodes[nodes < self.n_owned_nodes]
            r = self.V.tabulate_dof_coordinates()[nodes] - self.x0_tip
            inertia = self.comm.allreduce(np.einsum("ij,ij->", r, r) * np.eye(3) - r.T @ r)
            self._tip_face = (nodes, r, self.comm.allreduce(r.sum(axis=0)),
                              np.linalg.inv(inertia))
        nodes, r, r_sum, inertia_inv = self._tip_face
        X2 = X.reshape(X.shape[0], -1)
        u = X2.reshape(-1, 3, X2.shape[1])[nodes]                    # (n_face, 3, k)
        moment = self.comm.allreduce(np.cross(r[:, :, None], u, axis=1).sum(axis=0))
        centre = self.tip_displacement(X2)
        theta = inertia_inv @ (moment - np.cross(r_sum[:, None], centre, axis=0))
        out = np.vstack([centre, theta])
        return out if X.ndim == 2 else out[:, 0]

    def span_sections(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(x, S) for the columns of owned-entry arrays X (n_owned, k), real or complex: x (s,)
        the stations' distances from the root and S (4, s, k) the translation X, Y, Z of each
        station's section centroid and its rotation about X (SPEC section 10).

        :meth:`tip_section` generalised to every station: the least-squares rigid fit
        u_i ~ t + theta x r_i over the station's nodes, r_i = X_i - c with c the centroid on the
        X axis (SPEC section 9) at the node's own X, i.e. the 6 x 6 normal equations
        sum_i A_i^T A_i (t, theta) = sum_i A_i^T u_i with A_i = [1, -[r_i]x]. A station is a node
        layer (the nodes that share an X to 1e-6 of the length, at least half as many as the
        largest layer, and able to fix a rigid motion): every layer of the generated hexahedral
        meshes. The nodes in no such layer (an imported tetrahedral mesh between its root and
        tip planes) are binned by X into slabs of equal width, as many as give each slab about
        the mean node count of the layers, and each slab is one more station at its nodes' mean
        X: a field linear in X over the slab is then fitted at that X to second order in the
        slab width. The fit is one sparse (6 s, n_owned) operator per rank, built on the first
        call; the products are summed over the ranks, so every rank gets the same result.
        Collective on ``comm``."""
        x, op = self._span_fit
        X2 = X.reshape(X.shape[0], -1)
        local = np.asarray(op @ X2) if X2.shape[0] else np.zeros((op.shape[0], X2.shape[1]),
                                                                  dtype=X2.dtype)
        S = self.comm.allreduce(local).reshape(x.size, 6, X2.shape[1])[:, :4]
        S = S.transpose(1, 0, 2)
        return x, (S if X.ndim == 2 else S[..., 0])

    def _station_normals(self, A: np.ndarray, which: np.ndarray, count: int):
        """(keep, inverse): which stations' 6 x 6 normal equations fix a rigid motion, and their
        inverses (zero where not). Collective."""
        normal = np.zeros((count, 6, 6))
        np.add.at(normal, which, np.einsum("nci,ncj->nij", A, A))
        normal = self.comm.allreduce(normal)
        keep = np.zeros(count, dtype=bool)
        inverse = np.zeros_like(normal)
        for j, N in enumerate(normal):
            ev = np.linalg.eigvalsh(N)
            if ev[0] > 1e-9 * ev[-1]:
                keep[j] = True
                inverse[j] = np.linalg.inv(N)
        return keep, inverse

    def _slabs(self, x: np.ndarray, which: np.ndarray, keep: np.ndarray, station: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        """(station index of each owned node, stations x ascending) with the nodes outside the
        kept layers binned into slabs (:meth:`span_sections`). Collective."""
        comm = self.comm
        loose = ~keep[which]
        n_loose = comm.allreduce(int(loose.sum()))
        per_layer = comm.allreduce(int((~loose).sum())) / max(int(keep.sum()), 1)
        n = max(1, int(round(n_loose / per_layer)))
        xl = x[loose]
        lo = comm.allreduce(float(xl.min()) if xl.size else np.inf, op=MPI.MIN)
        hi = comm.allreduce(float(xl.max()) if xl.size else -np.inf, op=MPI.MAX)
        slab = np.minimum((n * (xl - lo) / max(hi - lo, 1e-300)).astype(int), n - 1)
        sums = comm.allreduce(np.bincount(slab, weights=xl, minlength=n))
        counts = comm.allreduce(np.bincount(slab, minlength=n))
        full = counts > 0
        centres = np.concatenate([station[keep], sums[full] / counts[full]])
        group = np.empty(x.size, dtype=np.int64)
        group[~loose] = (np.cumsum(keep) - 1)[which[~loose]]
        group[loose] = int(keep.sum()) + (np.cumsum(full) - 1)[slab]
        order = np.argsort(centres, kind="stable")
        rank = np.empty_like(order)
        rank[order] = np.arange(order.size)
        return rank[group], centres[order]

    def tip_fit(self):
        """The (6, n_owned) sparse rows of :meth:`span_sections`' rigid fit for the tip layer
        (translation of its centroid and small rotation per owned entry; sum over the ranks).
        Collective on the first call."""
        x, op = self._span_fit
        if not abs(x[-1] - self.scene.geometry.length) <= 1e-6 * self.scene.geometry.length:
            raise FxflexError("tip_mass: the tip face's nodes fix no rigid motion")
        return op[-6:]

    @functools.cached_property
    def _span_fit(self):
        """(x, the sparse (6 s, n_owned) fit operator of :meth:`span_sections`). Collective."""
        from scipy import sparse

        g = self.scene.geometry
        tol = 1e-6 * g.length
        coords = self.node_coordinates()
        x = coords[:, 0] - g.hub_radius
        keys = np.rint(x / tol).astype(np.int64)
        layers = np.unique(np.concatenate(self.comm.allgather(np.unique(keys))))
        which = np.searchsorted(layers, keys)
        r = coords - np.column_stack([coords[:, 0], np.zeros((len(coords), 2))])
        # A_i = [I, -[r_i]x]: (n, 3, 6)
        A = np.zeros((len(coords), 3, 6))
        A[:, :, :3] = np.eye(3)
        A[:, 0, 4], A[:, 0, 5] = r[:, 2], -r[:, 1]
        A[:, 1, 3], A[:, 1, 5] = -r[:, 2], r[:, 0]
        A[:, 2, 3], A[:, 2, 4] = r[:, 1], -r[:, 0]
        keep, inverse = self._station_normals(A, which, layers.size)
        sizes = self.comm.allreduce(np.bincount(which, minlength=layers.size))
        keep &= sizes >= sizes.max() / 2
        station = layers * tol
        if self.comm.allreduce(int(np.count_nonzero(~keep[which]))):
            which, station = self._slabs(x, which, keep, station)
            keep, inverse = self._station_normals(A, which, station.size)
        index = np.cumsum(keep) - 1
        mine = keep[which]
        # rows 6 index(station) + a, columns 3 node + c, values (N^-1 A_i^T)[a, c]
        block = np.einsum("nab,ncb->nac", inverse[which[mine]], A[mine])
        nodes = np.flatnonzero(mine)
        rows = (6 * index[which[mine]])[:, None, None] + np.arange(6)[None, :, None]
        cols = (3 * nodes)[:, None, None] + np.arange(3)[None, None, :]
        rows, cols = np.broadcast_arrays(rows, cols)
        op = sparse.csr_matrix((block.ravel(), (rows.ravel(), cols.ravel())),
                               shape=(6 * int(keep.sum()), self.n_owned))
        return station[keep], op

    def tip_relative(self, array: np.ndarray, phi: float = 0.0) -> np.ndarray:
        """Rotating-frame deflection U = A^T (x0 + u) - x0 of the tip centre for an inertial
        displacement array (SPEC section 2); phi = 0 for arrays already in O-XYZ."""
        u = self.tip_displacement(array)
        if phi == 0.0:
            return u
        A = rotation_z(phi)
        return A.T @ (self.x0_tip + u) - self.x0_tip
