"""Beam formulations of the paper's Sect. 3: LEBB (:mod:`.lebb`), NEBB (:mod:`.nebb`) and ANCF
(:mod:`.ancf`), each with ``build(scene, comm, options)`` and ``dof_count(scene)``.

Shared pieces: basix element tables (:mod:`.elements`), the beam line and its sections
(:mod:`.line`), the floating frame of LEBB/NEBB (:mod:`.frame`), the invariant-matrix engine of the
nonlinear forces (:mod:`.invariants`); the dense linear algebra is :mod:`fxflex.numerics.dense`
(:mod:`.linear` keeps the old import path).
"""

__all__ = ["ancf", "elements", "frame", "invariants", "lebb", "line", "linear", "nebb"]
