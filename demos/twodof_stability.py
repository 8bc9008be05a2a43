# %% [markdown]
# # The paper's two-DOF rotating system: five stability cases (Sect. 4.1, Eq. 61-64)
#
# Eq. 61, u'' + A(Omega t) K_L A^T(Omega t) u = 0 with K_L = diag(K_L1, K_L2): a stiffness that
# turns with the body. Seen from the rotating frame (U = A^T u) it is Eq. 62,
# U'' + 2 Omega J U' + (K_L - Omega^2 I) U = 0, with the roots of Eq. 63. Here K_L1 = 4,
# K_L2 = 1 (rad/s)^2 and one speed per case. For each case: the definiteness of K_L - Omega^2 I,
# the paper's verdict, the roots (Eq. 63 against the companion eigenvalues), and Eq. 61 itself
# integrated over 200 s by the generic central-difference driver from a small displacement.

# %%
import numpy as np

from fxflex.analysis.twodof import (CASES, behaviour, case_systems, eq63_roots, integrate,
                                    measured_growth)

undamped = case_systems()
print("case  Omega^2  K_L - Omega^2 I           paper     eigenvalues  Eq. 61 in time"
      "                 Eq. 64")
results = {}
for n, s in undamped.items():
    lam = s.eigenvalues()
    roots = eq63_roots(s.k1, s.k2, s.omega)
    # Eq. 63 and the companion form: the same four roots
    assert all(np.abs(roots - x).min() < 1e-6 for x in lam)
    g = measured_growth(integrate(s))
    results[n] = (s.stable(), behaviour(g), g)
    print(f"  {n}   {s.omega**2:6.3f}   {s.stiffness_definiteness():24s}  {CASES[n][1]:8s}  "
          f"{'stable' if s.stable() else 'unstable':11s}  {behaviour(g):11s} "
          f"(x{g['factor']:.3g}, ~t^{g['power']:.2f})  "
          f"{'stable' if s.eq64_stable() else 'unstable'}")

# %% [markdown]
# The paper's verdicts hold without damping. Case 4 (Omega^2 = K_L1) makes K_L - Omega^2 I
# *negative* semi-definite, diag(0, K_L2 - K_L1), not positive as printed; the double zero root has
# one eigenvector and |U| grows linearly (t^1), as in case 5. Case 1 is held by the gyroscopic
# term alone (Eq. 64, without it, is unstable there).
#
# Now the same with relative damping c = 0.1 1/s (the paper's Eq. 15-16 model: the rotating-frame
# rate is damped). Kelvin-Tait-Chetaev: an even number of negative stiffnesses held by gyroscopic
# coupling is lost under damping, so case 1 turns unstable, at the rate of its eigenvalue.

# %%
damped = case_systems(c=0.1, damping="relative")
print("case  eigenvalue max Re  verdict    Eq. 61 in time: behaviour, fitted rate")
for n, s in damped.items():
    lam = s.eigenvalues()
    g = measured_growth(integrate(s))
    results[n, "damped"] = (s.stable(), behaviour(g), g, lam.real.max())
    print(f"  {n}   {lam.real.max():+.5f}          {'stable' if s.stable() else 'unstable':9s}  "
          f"{behaviour(g):11s} {g['rate']:+.5f} 1/s")

# %% [markdown]
# With the absolute model (damping of the inertial rate, which acts like external damping) the
# circulatory term c Omega J cancels the destabilising part: case 1 stays stable.

# %%
absolute = case_systems(c=0.1, damping="absolute")
print("absolute damping, case 1: max Re lambda "
      f"{absolute[1].eigenvalues().real.max():+.5f}, "
      f"{'stable' if absolute[1].stable() else 'unstable'}")

# %% the checked values
for n, (verdict, word, g) in ((n, results[n]) for n in CASES):
    assert verdict == (CASES[n][1] == "stable")
assert [results[n][1] for n in CASES] == ["bounded", "exponential", "bounded", "polynomial",
                                          "polynomial"]
assert undamped[4].stiffness_definiteness() == "negative semi-definite"
stable1, word1, g1, rate1 = results[1, "damped"]
assert not stable1 and word1 == "exponential" and abs(g1["rate"] / rate1 - 1) < 0.05
assert absolute[1].stable()
print(f"damped case 1: eigenvalue growth {rate1:.5f} 1/s, integrated {g1['rate']:.5f} 1/s")
