"""The time loop: sampling, divergence stop, and the explicit schemes' order on an oscillator."""

import numpy as np
import pytest

from mpi4py import MPI

from fxflex.formulation import FormulationBase
from fxflex.scene import Scene
from fxflex.time import AB2, CentralDifference, simulate


class Oscillator(FormulationBase):
    """q'' = -w^2 q - 2 zeta w q' (one dof), behind the Formulation interface."""

    method = "oscillator"

    def __init__(self, w=2.0, zeta=0.05, q0=0.1):
        self.w, self.zeta, self.q0 = w, zeta, q0
        self.scene, self.dof, self.comm = Scene(), 1, MPI.COMM_SELF

    def initial_state(self):
        return np.array([self.q0]), np.array([0.0])

    def constrain(self, t, q, v):
        pass

    def acceleration(self, t, q, v, out):
        out[:] = -self.w**2 * q - 2 * self.zeta * self.w * v

    def tip(self, t, q):
        return np.array([q[0], 0.0, 0.0])

    def exact(self, t):
        w, z = self.w, self.zeta
        wd = w * np.sqrt(1 - z * z)
        return self.q0 * np.exp(-z * w * t) * (np.cos(wd * t) + z * w / wd * np.sin(wd * t))


@pytest.mark.parametrize("sample_every", [1, 7, 100, 250, 1000])
def test_samples_every_n_steps_and_at_the_end(sample_every):
    times = []
    res = simulate(Oscillator(), "cd", 1e-3, 2.345, sample_every=sample_every,
                   on_sample=lambda t, tip, ex, q: times.append(t))
    assert res.diverged is None and res.steps == 2345
    n = res.steps
    expected = [k * 1e-3 for k in range(0, n + 1, sample_every)]
    if n % sample_every:
        expected.append(n * 1e-3)
    assert np.allclose(times, expected) and res.samples == len(expected)


@pytest.mark.parametrize("scheme", ["ab2", "cd"])
def test_second_order_and_history(scheme):
    errors = []
    for h in (1e-2, 5e-3, 2.5e-3):
        osc = Oscillator()
        res = simulate(osc, scheme, h, 5.0, keep_history=True)
        # times are t0 + k dt (the driver), one rounding, not a sum of steps
        assert res.diverged is None and abs(res.t - 5.0) < 1e-12
        hist = np.array(res.history)
        # the largest error over the history: at a single time the leading term may vanish
        errors.append(np.max(np.abs(hist[:, 1] - osc.exact(hist[:, 0]))))
    order = np.log2(np.array(errors[:-1]) / errors[1:])
    assert np.all(np.abs(order - 2) < 0.1), order


def test_divergence_stops_early_with_a_reason():
    osc = Oscillator(w=1e3, zeta=0.0, q0=1e-3)
    res = simulate(osc, "cd", 2.5e-3, 1.0, sample_every=1000)   # w h = 2.5 > 2
    assert res.diverged is not None and res.t < 1.0
    assert "beyond" in res.diverged["reason"] or "non-finite" in res.diverged["reason"]


class Linear(FormulationBase):
    """q'' = A q + B q' on two coordinates: the schemes' steps are written out below."""

    method = "linear"

    def __init__(self):
        self.A = np.array([[-4.0, 1.0], [0.5, -9.0]])
        self.B = np.array([[-0.1, 0.02], [0.0, -0.3]])

    def constrain(self, t, q, v):
        pass

    def acceleration(self, t, q, v, out):
        out[:] = self.A @ q + self.B @ v


def test_exported_schemes_take_the_documented_steps():
    """AB2: a Heun start, then y_{n+1} = y_n + h (3/2 f_n - 1/2 f_{n-1}); central difference:
    v_{1/2} = v_0 + h/2 a_0, q_{n+1} = q_n + h v_{n+1/2}, v_{n+3/2} = v_{n+1/2} + h a_{n+1}, with
    v_{n+1} = v_{n+1/2} + h/2 a_n for the damping force. Written out here on q'' = A q + B q'; the
    same operations in another order, so equal to a few ulps (1e-14 of the state, which is O(1))."""
    form, h, q0, v0 = Linear(), 0.05, np.array([1.0, -0.5]), np.array([0.2, 0.3])

    def f(q, v):
        return form.A @ q + form.B @ v

    q, v = q0.copy(), v0.copy()
    ab2 = AB2()
    ab2.start(form, 0.0, h, q, v)
    ab2.step(form, h, h, q, v)
    ys = [(q0, v0)]
    qs, vs = q0 + h * v0, v0 + h * f(q0, v0)                     # Heun predictor
    ys.append((q0 + h / 2 * (v0 + vs), v0 + h / 2 * (f(q0, v0) + f(qs, vs))))
    (qa, va), (qb, vb) = ys
    ys.append((qb + h * (1.5 * vb - 0.5 * va), vb + h * (1.5 * f(qb, vb) - 0.5 * f(qa, va))))
    np.testing.assert_allclose(np.r_[q, v], np.r_[ys[2]], rtol=0, atol=1e-14)

    q, v = q0.copy(), v0.copy()
    cd = CentralDifference()
    cd.start(form, 0.0, h, q, v)
    cd.step(form, h, h, q, v)
    a = f(q0, v0)
    v_half, qn = v0 + h / 2 * a, q0.copy()
    for _ in range(2):
        qn = qn + h * v_half
        vn = v_half + h / 2 * a
        a = f(qn, vn)
        v_half = v_half + h * a
    np.testing.assert_allclose(np.r_[q, v], np.r_[qn, vn], rtol=0, atol=1e-14)


class Poisoned(Oscillator):
    """The oscillator plus a second coordinate, unseen by the tip, that turns NaN at t = 0.5."""

    def initial_state(self):
        return np.array([self.q0, 0.0]), np.zeros(2)

    def acceleration(self, t, q, v, out):
        out[0] = -self.w**2 * q[0] - 2 * self.zeta * self.w * v[0]
        out[1] = np.nan if t >= 0.5 else 0.0


@pytest.mark.parametrize("scheme", ["ab2", "cd"])
def test_nan_anywhere_in_the_state_stops_without_writing_it(scheme):
    rows = []
    res = simulate(Poisoned(), scheme, 1e-3, 2.0, sample_every=7,
                   on_sample=lambda t, tip, ex, q: rows.append((t, *tip)))
    assert res.diverged is not None and res.diverged["kind"] == "non-finite"
    assert 0.5 <= res.diverged["time_s"] <= 0.5 + 0.1 + 1e-9     # within one check interval
    rows = np.array(rows)
    assert np.isfinite(rows).all() and rows[-1, 0] < res.diverged["time_s"]
    assert np.isfinite(res.tip).all() and res.t < res.diverged["time_s"]


@pytest.mark.parametrize("scheme", ["ab2", "cd"])
@pytest.mark.parametrize("at", [300, 301])          # a sample step and one in between
def test_resume_from_a_checkpoint_is_bitwise(scheme, at):
    from fxflex.time import Resume

    kept = {}

    def keep(step, q, v, arrays, samples):
        if step == at:
            kept.update(q=q.copy(), v=v.copy(), samples=samples,
                        arrays={k: a.copy() for k, a in arrays.items()})

    rows_a, rows_b = [], []
    full = simulate(Oscillator(), scheme, 1e-3, 1.0, sample_every=10, checkpoint_every=1,
                    on_checkpoint=keep, on_sample=lambda t, tip, ex, q: rows_a.append((t, *tip)))
    res = simulate(Oscillator(), scheme, 1e-3, 1.0, sample_every=10,
                   state=(kept["q"], kept["v"]),
                   resume=Resume(step=at, arrays=kept["arrays"], samples=kept["samples"]),
                   on_sample=lambda t, tip, ex, q: rows_b.append((t, *tip)))
    assert res.steps == full.steps == 1000 and res.diverged is None
    assert rows_a[-len(rows_b):] == rows_b and len(rows_a) == kept["samples"] + len(rows_b)
    assert res.samples == full.samples and np.array_equal(res.tip, full.tip)
