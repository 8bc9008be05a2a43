"""Campbell branches followed from speed to speed by the modal assurance criterion (SPEC 10).

At each speed the formulation gives its lowest roots lambda and mode vectors x (``rotating_modes``,
a few more than are reported, so that a branch can be followed when it leaves the lowest ``n``).
The mode of a branch at the previous speed, x_i, and each candidate y_j at the next are compared
by the mass-weighted modal assurance criterion

    MAC_ij = |x_i^H M y_j|^2 / ((x_i^H M x_i) (y_j^H M y_j)),

1 for the same shape (whatever its complex phase), 0 for M-orthogonal ones. M is the mass of the
linearisation in the coordinates of the mode vectors: the dense array of the beams and of the
reduced solids (FFRF, GCMS: their modal coordinates), and for TLF, whose PETSc matrices live only
for an eigensolve, the formulation's own ``mass_apply`` (the lumped or consistent mass in use) on
the free coordinates, the products summed over the ranks. The mass of a formulation does not
depend on the speed (but for a TLF tip body with extent along X, whose director mass
``mass_apply`` takes at the equilibrium of the last linearisation: a weighting, nearly the same
at both), so one M serves both sides. The branches take the candidates of the
assignment that maximises the sum of the MAC (``scipy.optimize.linear_sum_assignment`` on
1 - MAC, the Hungarian method), so two branches never share a mode. Past a divergence an
oscillating pair becomes two real roots +-a with the same shape; the growing one continues the
branch (the decaying one costs :data:`DECAYING_REAL` more), as the plot has always drawn it.

Where a branch's MAC to the previous speed is below ``threshold`` (0.9) the interval is bisected,
up to ``levels`` times; a MAC still below it after that is reported (``low_mac``) and marked in the
PNG. Each branch carries the family of its mode at the first speed (the largest participation,
:mod:`fxflex.analysis.shapes`) and an ordinal label by frequency at the first
speed within its family ("1st out-of-plane", "2nd in-plane", ...). Note that a branch keeps its
identity by continuity of shape, not of family: through a veering (an avoided crossing of two
coupled modes, e.g. flap 1 and edge 1 of the twisted default blade at 5000-7000 rpm) the shapes
exchange gradually along each branch, so a branch's family can end in another family
(``directions``); where the modes truly cross (uncoupled, the untwisted blade) each branch keeps
its shape and family while the sorted order swaps them.

Resonances: where a branch frequency f(rpm) crosses the h-th multiple of the rotation frequency,
h rpm / 60 (h = 1..4), the speed by linear interpolation of the sign change of f - h rpm / 60.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Sample", "Branch", "Tracking", "mass_times", "mac_matrix", "assign",
           "track", "resonances", "ordinal", "HARMONICS", "MAC_THRESHOLD", "REFINE_LEVELS",
           "EXTRA_MODES", "DECAYING_REAL"]

#: multiples of the rotation frequency whose crossings are listed
HARMONICS = (1, 2, 3, 4)
#: a MAC to the previous speed below this refines the speed step
MAC_THRESHOLD = 0.9
#: bisections of one requested interval at most
REFINE_LEVELS = 4
#: modes computed beyond the ``n`` reported, for branches that leave the lowest ``n``
EXTRA_MODES = 4
#: added cost of a decaying real root where a growing one exists (divergence: the growing one
#: continues the branch; their shapes are alike, so this only decides between near-equal MACs)
DECAYING_REAL = 0.05


@dataclass
class Sample:
    """The modes at one speed: the reported ones (``modes``, SPEC section 8) and the candidates
    the branches are drawn from (``lam`` (k,), ``X`` this rank's rows, ``MX`` = M X)."""

    rpm: float
    modes: object                   # fxflex.analysis.modes.Modes, the ``n`` lowest
    lam: np.ndarray
    X: np.ndarray
    MX: np.ndarray
    labels: list[str]               # family of each candidate (largest participation)
    comm: object | None             # communicator to sum products over (None: replicated rows)
    requested: bool = True          # a speed asked for, not one added by refinement


@dataclass
class Branch:
    """One tracked branch: a value per speed of :attr:`Tracking.rpm`."""

    label: str
    family: str
    index: np.ndarray               # (s,) candidate index at each speed (-1: none)
    eigenvalues: np.ndarray         # (s,) complex (NaN where none)
    mac: np.ndarray                 # (s,) MAC to the previous speed, the first 1
    directions: list[str]           # family at each speed (largest participation)

    @property
    def frequencies_hz(self) -> np.ndarray:
        return np.abs(self.eigenvalues.imag) / (2.0 * math.pi)

    @property
    def growth_rates(self) -> np.ndarray:
        return self.eigenvalues.real

    @property
    def damping_ratios(self) -> np.ndarray:
        """-Re lambda / |lambda| (0 for a zero root)."""
        from fxflex.numerics.qep import damping_ratios
        return damping_ratios(self.eigenvalues)

    def to_dict(self) -> dict:
        """The SPEC section 10 fields of a branch, and its family per speed."""
        return {"label": self.label, "family": self.family,
                "frequencies_hz": self.frequencies_hz.tolist(),
                "growth_rates": self.growth_rates.tolist(),
                "damping_ratios": self.damping_ratios.tolist(), "mac": self.mac.tolist(),
                "directions": list(self.directions)}


@dataclass
class Tracking:
    """Tracked Campbell branches over the (possibly refined) speeds ``rpm``."""

    method: str
    rpm: np.ndarray                 # (s,) ascending, requested and refined speeds
    samples: list[Sample]
    branches: list[Branch]
    threshold: float = MAC_THRESHOLD
    seconds: float = 0.0
    refined: int = 0                # speeds added by refinement
    resonances: list[dict] = field(default_factory=list)

    @property
    def requested(self) -> np.ndarray:
        return np.array([s.requested for s in self.samples])

    @property
    def modes(self) -> list:
        return [s.modes for s in self.samples]

    def low_mac(self) -> list[tuple[str, float, float]]:
        """(branch label, rpm, MAC) where a MAC to the previous speed stayed below the
        threshold after refinement."""
        return [(b.label, float(self.rpm[i]), float(b.mac[i])) for b in self.branches
                for i in np.flatnonzero(b.mac < self.threshold)]

    def to_dict(self) -> dict:
        """``rpm``, ``branches`` and ``resonances`` of SPEC section 10."""
        return {"rpm": self.rpm.tolist(), "branches": [b.to_dict() for b in self.branches],
                "resonances": list(self.resonances)}


def ordinal(k: int) -> str:
    """1 -> '1st', 2 -> '2nd', 11 -> '11th', 23 -> '23rd'."""
    suffix = "th" if 10 <= k % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(k % 10, "th")
    return f"{k}{suffix}"


def mass_times(form, X: np.ndarray) -> np.ndarray:
    """M X in the coordinates of the mode vectors (module docstring): the dense linearisation's
    mass, or for a distributed one (TLF) ``form.mass_apply`` on the free coordinates of this
    rank. Collective for TLF."""
    lin = form.linearisation()
    if lin.kind == "dense":
        return lin.M @ X
    free = lin.free                 # TLF's linearisation: owned-entry index of each coordinate
    full = np.zeros(lin.n_owned)
    out = np.zeros(lin.n_owned)
    MX = np.empty(X.shape, dtype=complex)
    for j in range(X.shape[1]):
        parts = []
        for part in (X[:, j].real, X[:, j].imag):
            full[:] = 0.0
            full[free] = part
            form.mass_apply(full, out)
            parts.append(out[free].copy())
        MX[:, j] = parts[0] + 1j * parts[1]
    return MX


def _products(A: np.ndarray, B: np.ndarray, comm) -> np.ndarray:
    """A^H B, summed over ``comm`` when the rows are distributed."""
    local = A.conj().T @ B
    if comm is None:
        return local
    from mpi4py import MPI
    return comm.allreduce(local, op=MPI.SUM)


def mac_matrix(X: np.ndarray, MX: np.ndarray, Y: np.ndarray, MY: np.ndarray, comm=None
               ) -> np.ndarray:
    """MAC_ij = |x_i^H M y_j|^2 / ((x_i^H M x_i) (y_j^H M y_j)), (k_x, k_y); ``MX`` = M X,
    ``MY`` = M Y (pass X, Y themselves for the unweighted MAC)."""
    cross = _products(X, MY, comm)
    nx = np.real(np.einsum("ij,ij->j", X.conj(), MX))
    ny = np.real(np.einsum("ij,ij->j", Y.conj(), MY))
    if comm is not None:
        from mpi4py import MPI
        nx, ny = comm.allreduce(nx, op=MPI.SUM), comm.allreduce(ny, op=MPI.SUM)
    return np.abs(cross) ** 2 / np.outer(nx, ny)


def assign(mac: np.ndarray, lam: np.ndarray | None = None) -> np.ndarray:
    """Candidate index for each row of ``mac`` (branches x candidates) maximising the summed MAC
    (Hungarian method on 1 - MAC), -1 where there are fewer candidates than branches. With the
    candidates' roots ``lam``, a decaying real root costs DECAYING_REAL more where a growing real
    root exists (module docstring)."""
    from scipy.optimize import linear_sum_assignment

    cost = 1.0 - mac
    if lam is not None and lam.size:
        real = lam.imag == 0.0
        if np.any(real & (lam.real > 0.0)):
            cost = cost + DECAYING_REAL * (real & (lam.real < 0.0))[None, :]
    rows, cols = linear_sum_assignment(cost)
    out = np.full(mac.shape[0], -1, dtype=int)
    out[rows] = cols
    return out


def _step(prev: Sample, index: np.ndarray, nxt: Sample) -> tuple[np.ndarray, np.ndarray]:
    """(candidate index at ``nxt`` per branch, MAC to ``prev``) for branches at ``index`` of
    ``prev``; a branch without a mode at ``prev`` (-1) gets none."""
    live = index >= 0
    idx = np.full(index.size, -1, dtype=int)
    mac = np.full(index.size, np.nan)
    if not live.any() or not nxt.lam.size:
        return idx, mac
    sel = index[live]
    m = mac_matrix(prev.X[:, sel], prev.MX[:, sel], nxt.X, nxt.MX, prev.comm)
    got = assign(m, nxt.lam)
    rows = np.flatnonzero(live)
    ok = got >= 0
    idx[rows[ok]] = got[ok]
    mac[rows[ok]] = m[np.flatnonzero(ok), got[ok]]
    return idx, mac


def track(sample_at, speeds, pairs: int, *, method: str = "",
          threshold: float = MAC_THRESHOLD, levels: int = REFINE_LEVELS,
          progress=None) -> Tracking:
    """Branches of the ``pairs`` lowest modes at ``speeds[0]`` followed over ``speeds``
    (ascending rpm) by MAC, each interval bisected up to ``levels`` times where a branch's MAC
    falls below ``threshold`` (module docstring). ``sample_at(rpm, requested)`` gives the
    :class:`Sample` at a speed (:func:`fxflex.analysis.modes.sample_of` of the formulation
    there); ``progress(sample)`` is called after each speed computed. Collective for TLF."""
    t0 = time.perf_counter()
    samples: list[Sample] = []
    indices: list[np.ndarray] = []
    macs: list[np.ndarray] = []

    def compute(rpm: float, requested: bool) -> Sample:
        s = sample_at(float(rpm), requested)
        if progress is not None:
            progress(s)
        return s

    def accept(s: Sample, idx: np.ndarray, mac: np.ndarray) -> None:
        samples.append(s)
        indices.append(idx)
        macs.append(mac)

    def advance(nxt: Sample, depth: int) -> None:
        """Track from the last accepted sample to ``nxt``, bisecting below the threshold."""
        prev, index = samples[-1], indices[-1]
        idx, mac = _step(prev, index, nxt)
        if depth < levels and np.any(mac[index >= 0] < threshold):
            mid = compute(0.5 * (prev.rpm + nxt.rpm), False)
            advance(mid, depth + 1)
            advance(nxt, depth + 1)
            return
        accept(nxt, idx, mac)

    speeds = [float(r) for r in speeds]
    first = compute(speeds[0], True)
    k = min(pairs, first.lam.size)
    accept(first, np.arange(k), np.ones(k))
    for rpm in speeds[1:]:
        advance(compute(rpm, True), 0)
    index = np.array(indices)                     # (s, k)
    mac = np.array(macs)
    rpm = np.array([s.rpm for s in samples])
    branches = _branches(samples, index, mac)
    out = Tracking(method=method, rpm=rpm, samples=samples, branches=branches,
                   threshold=threshold, refined=sum(not s.requested for s in samples))
    out.resonances = [{"branch": b.label, "harmonic": h, "rpm": r}
                      for b in branches for h, r in resonances(rpm, b.frequencies_hz)]
    out.seconds = time.perf_counter() - t0
    return out


def _branches(samples: list[Sample], index: np.ndarray, mac: np.ndarray) -> list[Branch]:
    """Branch objects from the candidate index table, labelled by family at the first speed."""
    first = samples[0]
    order = np.lexsort((-first.lam.real[index[0]], np.abs(first.lam.imag[index[0]])))
    count: dict[str, int] = {}
    labels = {}
    for b in order:
        fam = first.labels[index[0, b]]
        count[fam] = count.get(fam, 0) + 1
        labels[b] = (fam, f"{ordinal(count[fam])} {fam}")
    out = []
    for b in range(index.shape[1]):
        lam = np.array([s.lam[i] if i >= 0 else complex(np.nan, np.nan)
                        for s, i in zip(samples, index[:, b])])
        dirs = [s.labels[i] if i >= 0 else "" for s, i in zip(samples, index[:, b])]
        fam, label = labels[b]
        out.append(Branch(label=label, family=fam, index=index[:, b].copy(), eigenvalues=lam,
                          mac=mac[:, b].copy(), directions=dirs))
    return out


def resonances(rpm, freq_hz, harmonics=HARMONICS) -> list[tuple[int, float]]:
    """(harmonic, rpm) where ``freq_hz`` crosses harmonic x rpm / 60: linear interpolation of the
    sign change of f - h rpm / 60 between neighbouring speeds (a speed where it is exactly 0
    counts once; NaN entries break the branch)."""
    rpm = np.asarray(rpm, dtype=float)
    f = np.asarray(freq_hz, dtype=float)
    out = []
    for h in harmonics:
        d = f - h * rpm / 60.0
        for i in range(rpm.size - 1):
            a, b = d[i], d[i + 1]
            if not (np.isfinite(a) and np.isfinite(b)):
                continue
            if i == 0 and a == 0.0 and rpm[0] > 0.0:
                out.append((h, float(rpm[0])))
            if a != 0.0 and (b == 0.0 or (a > 0.0) != (b > 0.0)):
                out.append((h, float(rpm[i] + (rpm[i + 1] - rpm[i]) * a / (a - b))))
    return sorted(out, key=lambda hr: (hr[1], hr[0]))
