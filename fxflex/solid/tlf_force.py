"""TLF internal force Q_k(u) assembled from the SVK residual form (paper Eq. 30-33, the ``ufl``
route of --force-eval), and the choice between it and the invariant-matrix route
(:class:`fxflex.solid.tlf_invariants.InvariantForce`, Eq. 33, 35)."""

from __future__ import annotations

import time

import numpy as np
from dolfinx import cpp, fem

from fxflex.solid import forms
from fxflex.solid.tlf_invariants import InvariantForce
from fxflex.solid.model import SolidModel

__all__ = ["KERNEL_FLAGS", "UflForce", "make_force"]

#: C flags for the residual kernel of the time loop: vector instructions of this CPU and
#: reassociated sums (the kernel's sums over the cell's nodes then vectorise), NaN and inf still
#: propagate (no -ffinite-math-only). 4.7 -> 3.7 ms per evaluation on the default mesh.
KERNEL_FLAGS = ["-O2", "-march=native", "-fno-math-errno", "-fno-trapping-math",
                "-fno-signed-zeros", "-fassociative-math"]


class UflForce:
    """Q_k(u) by assembling the SVK residual int (F S) : grad v (Eq. 33) each evaluation.

    The coefficient array of the form is packed in place from the local displacement array (one
    gather), so an evaluation allocates nothing in Python; ``apply(u, out)`` takes and fills local
    (owned + ghost) arrays, ghost entries holding partial sums like any assembled vector.
    """

    def __init__(self, model: SolidModel):
        t0 = time.perf_counter()
        self.u = fem.Function(model.V)
        self.form = fem.form(forms.svk_residual(model.scene.material, self.u, model.u_test,
                                                model.dx),
                             jit_params={"cffi_extra_compile_args": KERNEL_FLAGS})
        self.constants = cpp.fem.pack_constants(self.form)
        self.coeffs = cpp.fem.pack_coefficients(self.form)
        (self._packed,) = self.coeffs.values()          # (cells, 3 x nodes), refilled in place
        n_cells = self._packed.shape[0]
        per_cell = model.V.dofmap.dof_layout.num_dofs    # 8 (Q1) or 27 (Q2) nodes
        nodes = model.V.dofmap.list.array.reshape(-1, per_cell)[:n_cells]
        self._gather = (3 * nodes[:, :, None] + np.arange(3)).reshape(-1)
        self._flat = self._packed.reshape(-1)
        self.build_time = time.perf_counter() - t0

    def apply(self, u: np.ndarray, out: np.ndarray) -> None:
        np.take(u, self._gather, out=self._flat, mode="clip")   # "raise" buffers out
        out[:] = 0.0
        cpp.fem.assemble_vector(out, self.form, self.constants, self.coeffs)

    def memory_bytes(self) -> dict[str, int]:
        """Bytes held beyond the mesh: the packed coefficient and its gather indices."""
        return {"coefficients": self._packed.nbytes, "gather_index": self._gather.nbytes}


def make_force(kind: str, model: SolidModel) -> UflForce | InvariantForce:
    """The internal force route ``kind`` (``ufl`` or ``invariant``, --force-eval) on the model.
    The invariant route is Q1 only: on Q2 it refuses with the memory it would need
    (:func:`fxflex.solid.tlf_invariants.refuse_degree`)."""
    if kind == "ufl":
        return UflForce(model)
    return InvariantForce(model)
