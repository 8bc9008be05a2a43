"""What FFRF and GCMS share: mesh integrals projected on a modal basis, once, and the small
dense system that is then integrated, linearised and solved for its steady state.

Preprocessing runs distributed on the solid model's communicator: a basis is an (n_owned, k)
array of this rank's entries, products with the assembled PETSc matrices are distributed
mat-vecs, and every projection X^T A Y is reduced with ``allreduce``. What comes out is a few
dense matrices of the size of the basis, replicated on every rank; from there on the formulation
lives on ``MPI.COMM_SELF`` and a time step costs O(k^2) and never touches the mesh.

Nodal operators. On Q1 hexahedra the mass matrix is isotropic (the same scalar mass between two
nodes for each direction), so for the 3x3 matrices B of NOTES.md (S, P, G3 = e_z e_z^T) the
mass-coupling forms are int rho (B u) . v = M B_d, with B_d acting node by node. The inertia
shape integrals of the paper's Appendix become (derivation in docs/reduced.md)

    G = Phi^T M S_d Phi,  N = Phi^T M P_d Phi,  g = int rho Phi^T S X0,  n = int rho Phi^T P X0,
    J0 = int rho X0^T P X0,

and the GCMS constant matrices are projections of K_L and M on [P_d Phi, S_d Phi, G3_d Phi].

Cache. These projections (a few dense matrices of the basis size, the same on every rank) depend
on the geometry, material, mesh, external load and mode count, never on the speed or the
damping, so they are stored on disk (:mod:`fxflex.cache`, kind ``reduced``) under
:func:`reduced_key`. A build that finds them needs no mesh, assembly or eigensolve; the mesh,
operators and modes are then built only if something asks for them (``model``, ``data``,
``modes``: the ``--fields`` writer, tests, studies).

Rotating-frame system. Both methods, written about the rotating frame at constant speed Omega
(FFRF in its modal coordinates, GCMS in coordinates rotated back with A^T, SPEC section 6), have
the form

    M_r z'' + (2 Omega G_r + (c/rho) M_r) z' + (K_r - Omega^2 N_r + a (c/rho) Omega G_r) z
        = f_r + Omega^2 n_r,

a = 1 for the absolute damping model (Eq. 67, the circulatory term) and 0 for the relative one
(Eq. 15-16, 22-23); M_r = I but for GCMS with a tip body's Pi_XX (I + M_d, gcms.TipDirector).
:class:`RotatingSystem` holds (K_r, G_r, N_r, f_r, n_r, M_r) and the tip rows;
:class:`ReducedFormulation` derives from it the steady state, the linearisation (M, C, K) and its
eigenvalues (growth rate, highest frequency) for both methods.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from mpi4py import MPI

from fxflex import cache
from fxflex.numerics.dense import DenseLU
from fxflex.numerics.growth import ab2_root
from fxflex.numerics.qep import DenseLinearisation
from fxflex.formulation import FormulationBase, SteadyState
from fxflex.scene import Drive, Scene

if TYPE_CHECKING:                   # a cache hit needs neither PETSc nor dolfinx: imported on use
    from petsc4py import PETSc

    from fxflex.io.fields import FieldWriter
    from fxflex.solid.model import SolidModel

__all__ = ["nodal", "mat_apply", "inner", "tip_rows", "MeshData", "mesh_data",
           "director_corrections",
           "AffineStack", "RotatingSystem", "ReducedFormulation",
           "rotation_weights", "ab2_root", "reduced_key", "load_reduced", "save_reduced"]


# -- distributed projections ----------------------------------------------------------------------

def nodal(B: np.ndarray, X: np.ndarray) -> np.ndarray:
    """B_d X: the 3x3 matrix B applied node by node to nodal arrays X (n_owned,) or (n_owned, k)."""
    shape = X.shape
    Y = X.reshape(-1, 3, *shape[1:])
    return np.einsum("ij,nj...->ni...", B, Y).reshape(shape)


def mat_apply(A: PETSc.Mat, X: np.ndarray) -> np.ndarray:
    """A X column by column for owned-row arrays X (n_owned, k); distributed mat-vecs."""
    x, y = A.createVecRight(), A.createVecLeft()
    out = np.empty_like(X)
    for j in range(X.shape[1]):
        x.setArray(X[:, j])
        A.mult(x, y)
        out[:, j] = y.getArray(readonly=True)
    x.destroy()
    y.destroy()
    return out


def inner(comm, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """X^T Y over all ranks (owned entries only, so nothing is counted twice)."""
    return comm.allreduce(X.T @ Y)


def tip_rows(model: SolidModel, X: np.ndarray) -> np.ndarray:
    """(3, k): the tip-centre displacement of each column of X, on every rank."""
    return model.tip_displacement(X)


@dataclass
class MeshData:
    """Everything a reduced model takes from the mesh, as this rank's owned entries."""

    K: PETSc.Mat                # K_L with the clamp (1 on the clamped diagonal)
    M: PETSc.Mat                # M with the clamp (0 on the clamped diagonal)
    f_c: np.ndarray             # int rho N^T P X0 (centrifugal load per unit phi'^2)
    f_S: np.ndarray             # int rho N^T S X0 (tangential load per unit phi'')
    F: np.ndarray               # external load in O-XYZ after the ramp (line load + tip force)
    J0: float                   # int rho X0^T P X0: rigid moment of inertia about z
    load_torque: float          # sum over nodes of (S X0) . F: torque of F about z, undeformed
    timings: dict = field(default_factory=dict)
    #: a tip body's Pi_XX (FFRF: its director linearised at the reference, in M above and in
    #: the loads; :func:`director_corrections` for the invariants that M alone would get wrong)
    director: object = None


def mesh_data(model: SolidModel) -> MeshData:
    """Assemble K_L, M, the rigid-rotation inertia loads and the external load (once)."""
    import ufl
    from dolfinx import fem

    from fxflex.scene.kinematics import P3, S3
    from fxflex.solid.cms import mass_and_stiffness
    from fxflex.solid.tip_mass import tip_body

    t0 = time.perf_counter()
    K, M = mass_and_stiffness(model)
    n = model.n_owned
    f_c = model.vector(model.centrifugal_form()).getArray(readonly=True)[:n].copy()
    f_S = model.vector(model.euler_form()).getArray(readonly=True)[:n].copy()
    F = model.rotating_load().getArray(readonly=True)[:n].copy()
    X0 = model.X0
    J0 = model.comm.allreduce(fem.assemble_scalar(fem.form(
        model.rho * ufl.inner(ufl.dot(ufl.as_matrix(P3.tolist()), X0), X0) * model.dx)))
    body = tip_body(model)
    director = None
    if body is not None:                 # the tip body's rigid-rotation terms (tip_mass.py)
        f_c += body.load(P3)
        f_S += body.load(S3)
        J0 += body.second_moment(P3)
        director = body.director
        if director is not None:         # Pi_XX: n0 = e_X, n = n0 + J u (FFRF, linearised)
            Bn = director.normal(director.g0)[4]
            for B, f in ((P3, f_c), (S3, f_S)):
                director.add_spread(director.pi * (Bn.T @ (B @ np.array([1.0, 0.0, 0.0]))), f)
            J0 += director.pi * P3[0, 0]
    xyz = model.node_coordinates()
    load_torque = model.comm.allreduce(float(np.sum((xyz @ S3.T) * F.reshape(-1, 3))))
    return MeshData(K=K, M=M, f_c=f_c, f_S=f_S, F=F, J0=float(J0), load_torque=load_torque,
                    timings={"assemble": time.perf_counter() - t0}, director=director)


def director_corrections(data: MeshData, Phi: np.ndarray, BPhi: list) -> list:
    """For a tip body's Pi_XX on the FFRF (:class:`fxflex.numerics.director.Director`,
    linearised at the reference: n = e_X + J u, J = B_n0 W): M holds Pi_XX J^T J, so
    (M Phi)^T (B_d Phi) carries Pi_XX (J Phi)^T J B_d Phi where the body's coupling is
    Pi_XX (J Phi)^T B (J Phi) (the director does not commute with B_d: J B_d != B J). Returns
    the difference to add for each (B, B_d Phi) of ``BPhi``, (m, m) each; [] without one.
    Collective."""
    d = data.director
    if d is None:
        return []
    JPhi = d.reference_rows(Phi)
    return [d.pi * (JPhi.T @ B @ JPhi - JPhi.T @ d.reference_rows(BdPhi)) for B, BdPhi in BPhi]


# -- cache of the projections ---------------------------------------------------------------------

def reduced_key(scene: Scene, method: str, count: int, **extra) -> str:
    """Cache key of ``method``'s projections on ``count`` clamped modes of ``scene``'s mesh: mesh
    key (with the element degree, ``mesh.solid_degree``), material, load, count, ``extra`` (e.g.
    the Gram cut) and the producing source (the quadrature degree is SolidModel's default for the
    degree, covered by its source)."""
    from fxflex.mesh.solid import mesh_key
    from fxflex.solid.cms import CODE_MODULES
    from fxflex.solid.tip_mass import tip_key

    load = scene.load
    return cache.entry_key({
        "kind": method,
        "mesh": mesh_key(scene.geometry, scene.mesh.solid, scene.mesh.solid_degree),
        **({"degree": scene.mesh.solid_degree} if scene.mesh.solid_degree != 1 else {}),
        "material": dataclasses.asdict(scene.material),
        "load": {"line_load": load.line_load, "tip_force": list(load.tip_force)},
        "count": int(count), **tip_key(scene), **extra,
        "code": cache.code_version(*CODE_MODULES, __name__, f"fxflex.solid.{method}")})


def load_reduced(key: str, cls, comm):
    """The dataclass ``cls`` stored under ``key``, or None (on every rank unless all read it)."""
    data = cache.load("reduced", key)
    obj = None
    names = [f.name for f in dataclasses.fields(cls)]
    if data is not None and set(names) <= set(data):
        obj = cls(**{n: (float(data[n]) if data[n].ndim == 0 else data[n]) for n in names})
    return obj if comm.allreduce(obj is not None, op=MPI.LAND) else None


def save_reduced(key: str, obj, comm) -> None:
    """Store a dataclass of arrays and floats (replicated on every rank) from rank 0."""
    if comm.rank == 0:
        cache.save("reduced", key, {f.name: getattr(obj, f.name)
                                    for f in dataclasses.fields(obj)})


# -- the small dense system ------------------------------------------------------------------------

class AffineStack:
    """y -> sum_k w[k] A_k y for fixed (n, m) matrices A_k: the A_k are stacked so that the k
    products are one BLAS call, the weighted sum a second; nothing is allocated per call."""

    def __init__(self, mats):
        mats = [np.asarray(A, float) for A in mats]
        self.k, self.n = len(mats), mats[0].shape[0]
        self.A = np.ascontiguousarray(np.concatenate(mats, axis=0))
        self.z = np.empty(self.k * self.n)
        self.Z = self.z.reshape(self.k, self.n)
        self.w = np.ones(self.k)

    def apply(self, y: np.ndarray, out: np.ndarray) -> None:
        if self.k == 1:
            np.dot(self.A, y, out=out)
            if self.w[0] != 1.0:
                out *= self.w[0]
        else:
            np.dot(self.A, y, out=self.z)
            np.dot(self.w, self.Z, out=out)


@dataclass
class RotatingSystem:
    """The reduced equations about the rotating frame (module docstring), in coordinates z."""

    K: np.ndarray       # elastic stiffness K_r
    G: np.ndarray       # Coriolis / S-coupling, skew
    N: np.ndarray       # spin softening (symmetric)
    f: np.ndarray       # external load after the ramp
    n: np.ndarray       # centrifugal load per unit Omega^2
    tip: np.ndarray     # (3, k): tip-centre deflection in O-XYZ per unit z
    section: np.ndarray  # (6, k): tip-centre translation and tip-section rotation per unit z
    #: the mass, None for the identity (GCMS with a tip body's Pi_XX: I + M_d)
    M: np.ndarray | None = None


class ReducedFormulation(FormulationBase):
    """Common part of FFRF and GCMS: state layout, linearisation, eigenvalues, steady state.

    Subclasses set ``dof``, ``rot`` (:class:`RotatingSystem`) and the three operators of
    ``q'' = kstack(q) + cstack(v) + F @ fw`` with their per-step weights in ``_weights(t)``.
    """

    method = ""
    mesh_key = "mesh.solid"
    extra_columns = ("drive_torque_Nm",)
    #: the projections this build used (FFRFInvariants or GlobalModes): what :meth:`at` shares
    _projected = None
    #: projections handed to a build by :meth:`at`, used instead of the cache or the mesh
    _shared = None
    #: the build :meth:`at` derived this one from: its mesh, operators, clamped modes and
    #: root-stress map are this one's too, built (once, there) when either first asks
    _source = None

    def __init__(self, scene: Scene, build_comm, options=None):
        self.scene = scene
        self.build_comm = build_comm
        # the clamped modes' linear solver route ([solver] linear, resolved by build)
        self.linear = (options.linear if options is not None else None) or "direct"
        self.comm = MPI.COMM_SELF
        self.drive = Drive(scene.rotation)
        self.c_rho = scene.damping.c / scene.material.rho
        self.absolute = scene.damping.model == "absolute"
        # at rest (0 rpm) a spin-up is no spin-up: every rotation term is identically zero
        self.constant_speed = scene.rotation.profile == "constant" or self.drive.at_rest
        self.timings: dict[str, float] = {}
        self._root_map: np.ndarray | None = None
        self._lu: DenseLU | None = None

    # -- Formulation interface ---------------------------------------------------------------
    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Undeformed and at rest relative to the frame at t = 0 (SPEC section 1)."""
        return np.zeros(self.dof), np.zeros(self.dof)

    def constrain(self, t: float, q: np.ndarray, v: np.ndarray) -> None:
        """No constrained coordinates: the clamp is built into the modes."""

    def _setup_operators(self, kmats, cmats, fcols) -> None:
        self.kstack, self.cstack = AffineStack(kmats), AffineStack(cmats)
        self.F = np.ascontiguousarray(np.column_stack(fcols))
        self.fw = np.zeros(self.F.shape[1])
        self._tmp = np.empty(self.dof)
        self._acc = np.empty(self.dof)

    def acceleration(self, t: float, q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        self._weights(t)
        tmp = self._tmp
        self.kstack.apply(q, out)
        self.cstack.apply(v, tmp)
        out += tmp
        np.dot(self.F, self.fw, out=tmp)
        out += tmp

    def extras(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[float]:
        return (self.drive_torque(t, q, v),)

    # -- implicit integration (formulation.Implicit) ----------------------------------------------
    def force(self, t: float, q: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
        """F = q'' itself: the modal mass is the identity and nothing is constrained."""
        self.acceleration(t, q, v, out)

    def mass_apply(self, x: np.ndarray, out: np.ndarray) -> None:
        out[:] = x

    def factorize(self, t: float, q: np.ndarray, v: np.ndarray, m: float, c: float, k: float
                  ) -> DenseLU:
        """S = m I + c C_t + k K_t with the exact tangents of the linear reduced equations,
        K_t = -sum_i w_i(t) K_i and C_t = -sum_i w_i(t) C_i (the weighted blocks of
        ``acceleration``; GCMS's stiffness turns with phi, FFRF's only changes with the speed)."""
        self._weights(t)
        if self._lu is None:
            self._lu = DenseLU(self.dof)
            self._S = np.zeros((self.dof, self.dof))
        S, n, out = self._S, self.dof, self._lu.matrix
        np.dot(self.kstack.w, self.kstack.A.reshape(self.kstack.k, n * n), out=S.reshape(-1))
        np.multiply(S, -k, out=out)
        np.dot(self.cstack.w, self.cstack.A.reshape(self.cstack.k, n * n), out=S.reshape(-1))
        S *= c
        out -= S
        out.flat[::n + 1] += m
        return self._lu.factor()

    # -- rotating frame: steady state, linearisation, eigenvalues --------------------------------
    @property
    def omega_s(self) -> float:
        return self.scene.rotation.omega

    def linearise(self, steady: SteadyState | None = None) -> DenseLinearisation:
        """(M, C, K) of the reduced equations linearised about the steady state in the rotating
        frame: M = M_r, C = 2 Omega G_r + (c/rho) M_r (Coriolis + damping), K = K_r - Omega^2 N_r
        (+ (c/rho) Omega G_r, the circulatory term of the absolute damping model). The reduced
        equations are linear, so this does not depend on the steady state itself."""
        r, w = self.rot, self.omega_s
        M = np.eye(self.dof) if r.M is None else r.M
        C = 2.0 * w * r.G + self.c_rho * M
        K = r.K - w * w * r.N
        if self.absolute:
            K = K + self.c_rho * w * r.G
        return DenseLinearisation(M, C, K)

    def rotating_state(self, t: float, q: np.ndarray, v: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
        """(z, z') in the coordinates of :meth:`linearise` (FFRF: its own, relative to the
        rotating frame already)."""
        return q, v

    def mode_tip(self, X: np.ndarray) -> np.ndarray:
        """(6, k) tip translation and rotation (O-XYZ) of rotating-frame mode vectors X (k, ...)
        in the coordinates z of :class:`RotatingSystem`."""
        return self.rot.section @ X

    def mode_span(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(x, S) of rotating-frame mode vectors X (dof, k): the (4 s, dof) operator of
        :meth:`SolidModel.span_sections` applied to the nodal basis once (at phi = 0, where
        GCMS's inertial basis is the rotating one), then S = operator X (SPEC section 10). The
        first call is collective on the build communicator."""
        x, op = self._span_operator()
        S = np.tensordot(op, X, axes=(2, 0))
        return x.copy(), S

    def _span_operator(self) -> tuple[np.ndarray, np.ndarray]:
        """(x, (4, s, dof)): the span sections per unit z, the source build's when there is one
        (it does not depend on the speed or the damping)."""
        if self._source is not None:
            return self._source._span_operator()
        if self._span is None:
            basis, _ = self.nodal_basis()
            self._span = self.model.span_sections(basis)
        return self._span

    #: (x, operator) of :meth:`_span_operator`, built on first use
    _span: tuple[np.ndarray, np.ndarray] | None = None

    def omega_max(self) -> float:
        """Highest circular frequency max |lambda| of the linearised rotating system (rad/s)."""
        return float(np.max(np.abs(self.eigenvalues())))

    def ab2_growth_rate(self, dt: float) -> tuple[float, float]:
        """(ln|z| / dt, |lambda|) of the fastest-growing AB2 solution at step dt: z the larger root
        of z^2 - (1 + 3/2 dt lambda) z + 1/2 dt lambda = 0 for each eigenvalue lambda of the
        linearised rotating system. Exact for the constant-speed FFRF (a linear constant-
        coefficient system). For small dt |lambda| and lambda near the imaginary axis it tends to
        Re lambda + |lambda|^4 dt^3 / 4, the law of NOTES.md."""
        lam = self.eigenvalues()
        rate = np.log(ab2_root(dt * lam)) / dt
        i = int(np.argmax(rate))
        return float(rate[i]), float(abs(lam[i]))

    def steady_state(self) -> SteadyState:
        """(K_r - Omega^2 N_r [+ (c/rho) Omega G_r]) z = f_r + Omega^2 n_r at the scene's speed
        (the final speed of a spin-up): Eq. 59 with the time derivatives set to zero."""
        t0 = time.perf_counter()
        K = self.linearise().K
        r, w = self.rot, self.omega_s
        rhs = r.f + w * w * r.n
        z = np.linalg.solve(K, rhs)
        res = np.linalg.norm(K @ z - rhs) / max(np.linalg.norm(rhs), 1e-300)
        return SteadyState(tip=r.tip @ z, q=z, iterations=1, residuals=[float(res)],
                           converged=bool(np.all(np.isfinite(z))),
                           timings={"solve": time.perf_counter() - t0},
                           extra={"modes": int(self.dof)})

    def field_writer(self, path: str) -> FieldWriter:
        """``--fields``: an XDMF series of the displacement field rebuilt from the modal state,
        U in O-XYZ and u = A U in o-xyz (:mod:`fxflex.io.fields`). Collective on the build
        communicator: every rank writes the same replicated state."""
        from fxflex.io.fields import FieldWriter
        from fxflex.scene.kinematics import rotation_z

        m = self.model
        drive = self.drive
        basis, inertial = self.nodal_basis()

        def displacement(t: float, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            d = (basis @ q).reshape(-1, 3)
            A = rotation_z(drive.angle(t))
            u, U = (d, d @ A) if inertial else (d @ A.T, d)
            return u.reshape(-1), U.reshape(-1)

        return FieldWriter(m.comm, m.V, path, displacement)

    def nodal_basis(self) -> tuple[np.ndarray, bool]:
        """(B, inertial): this rank's owned displacement entries are B q, measured in o-xyz when
        ``inertial`` (GCMS) and in O-XYZ otherwise (FFRF)."""
        raise NotImplementedError

    def rotating_coordinates(self, t: float, q: np.ndarray) -> np.ndarray:
        """z with U = B z in O-XYZ (B from :meth:`nodal_basis`) for the state q at time t."""
        return q

    def root_stress(self, t: float, q: np.ndarray) -> np.ndarray:
        """sigma_X (Pa) at the four corners of the root section: the resultants of the Hooke
        stress (Eq. 12-14) in the root cells (:mod:`fxflex.solid.section`), linear in z, so
        projected on the basis once (first call collective on the build communicator)."""
        if self._root_map is None:
            self._root_map = self._root_resultants()
        return self.model.shape.axial_stress(
            0.0, self._root_map @ self.rotating_coordinates(t, q))

    def _root_resultants(self) -> np.ndarray:
        """The root-section resultants per unit z (independent of the speed and the damping:
        the source build's, when there is one)."""
        if self._source is not None:
            return self._source._root_resultants()
        if self._root_map is None:
            basis, _ = self.nodal_basis()
            self._root_map = self.model.root_section("hooke").resultant_matrix(basis)
        return self._root_map

    # -- mesh, operators and modes: built when first asked for ------------------------------------
    def _use(self, count: int, model: SolidModel | None, data: MeshData | None, modes) -> bool:
        """Take whatever the caller passes; the rest is built on demand (collective on the build
        comm). True when nothing was passed, so the projections may come from the cache."""
        if modes is not None and modes.count < count:
            raise ValueError(f"need {count} clamped modes, got {modes.count}")
        self._count = count
        self._model, self._data, self._modes = model, data, modes
        return model is None and data is None and modes is None and cache.enabled("reduced")

    @property
    def model(self) -> SolidModel:
        from fxflex.solid.model import SolidModel

        if self._model is None and self._source is not None:
            self._model = self._source.model
        if self._model is None:
            self._model = SolidModel(self.scene, self.build_comm)
            self.timings["mesh"] = self._model.timings.get("mesh", 0.0)
        return self._model

    @property
    def data(self) -> MeshData:
        if self._data is None and self._source is not None:
            self._data = self._source.data
        if self._data is None:
            self._data = mesh_data(self.model)
            self.timings["assemble"] = self._data.timings["assemble"]
        return self._data

    @property
    def modes(self):
        """The clamped modes (at least the first ``count``)."""
        from fxflex.solid.cms import clamped_modes

        if self._modes is None and self._source is not None:
            self._modes = self._source.modes
        if self._modes is None:
            t0 = time.perf_counter()
            d = self._data
            self._modes = clamped_modes(self.model, self._count, K=d.K if d else None,
                                        M=d.M if d else None, linear=self.linear)
            self.timings["eigenmodes"] = time.perf_counter() - t0
        return self._modes

    def _projections(self, key: str | None, cls, project):
        """The projections shared by :meth:`at`, else ``cls`` from the cache under ``key``, else
        ``project(model, data, Phi)`` (stored); kept as ``_projected`` for :meth:`at`."""
        if self._shared is not None:
            self._projected = self._shared
            return self._shared
        t0 = time.perf_counter()
        out = load_reduced(key, cls, self.build_comm) if key else None
        if out is not None:
            self.timings["cache_load"] = time.perf_counter() - t0
            self._projected = out
            return out
        data = self.data                       # assembled first: the eigensolve reuses K, M
        Phi = self.modes.vectors[:, : self._count]
        t1 = time.perf_counter()
        out = project(self.model, data, Phi)
        self.timings["invariants"] = time.perf_counter() - t1
        if key:
            save_reduced(key, out, self.build_comm)
        self._projected = out
        return out

    def at(self, *, rpm: float | None = None, damping: float | None = None,
           model: str | None = None) -> "ReducedFormulation":
        """The same method and options at another speed (rpm), damping coefficient c or damping
        model, sharing this build's projections -- the invariants on the modal basis, which
        depend on the mesh, material, load and mode count but never on the speed or the damping
        (module docstring) -- and its mesh, operators, clamped modes and root-stress map, now or
        when first asked for: only the few dense operators of the new speed and damping are
        formed (milliseconds). The numbers are those of a fresh ``build`` of that scene, whose
        projections come from the cache (``tests/test_at.py``)."""
        from fxflex.formulation import rescene

        scene = rescene(self.scene, rpm=rpm, damping=damping, model=model)
        cls = type(self)
        form = cls.__new__(cls)
        form._shared = self._projected          # read by _projections in the constructor
        form._source = self if self._source is None else self._source
        cls.__init__(form, scene, self.build_comm, self.options, model=self._model,
                     data=self._data, modes=self._modes)
        form.options = self.options
        return form

    def _drive_state(self, t: float) -> tuple[float, float, float]:
        return self.drive.state(t)

    def ramp(self, t: float) -> float:
        return self.scene.load.factor(t)


def rotation_weights(phi: float) -> tuple[float, float, float, float]:
    """(cos phi, sin phi, cos 2 phi, sin 2 phi)."""
    c, s = math.cos(phi), math.sin(phi)
    return c, s, c * c - s * s, 2.0 * s * c
