# %% [markdown]
# # Speed, stiffening and stability of the three beam models
#
# The paper's Sect. 4.1 on the default scene (twisted, tapered beam, line load, c = 1000):
# steady deflections in the rotating frame at 1000, 5000 and 10000 rpm, and the largest real
# part of the eigenvalues of the motion linearised about them (Coriolis and damping included).
# LEBB is linear: its stiffness K_L - Omega^2 M_rr6 (Eq. 59) loses definiteness before
# 10000 rpm and the equilibrium turns unstable. NEBB and ANCF stiffen with speed and stay stable.

# %%
from fxflex.formulation import build
from fxflex.scene import Scene

growth = {}
for method in ("lebb", "nebb", "ancf"):
    for rpm in (1000.0, 5000.0, 10000.0):
        form = build(method, Scene().replace(**{"rotation.rpm": rpm}), None)
        tip = 1e3 * form.steady_state().tip
        rate, _ = form.growth_rate()
        growth[method, rpm] = rate
        print(f"{method} {rpm:6.0f} rpm: tip (mm) {tip[0]:+9.5f} {tip[1]:+9.5f} {tip[2]:+9.5f}"
              f"   max Re(lambda) {rate:+10.4g} 1/s  {'stable' if rate <= 0 else 'UNSTABLE'}")

# %% the checked value: only LEBB is unstable at 10000 rpm
assert growth["lebb", 10000.0] > 0 and growth["nebb", 10000.0] < 0 and growth["ancf", 10000.0] < 0
print(f"LEBB at 10000 rpm grows at {growth['lebb', 10000.0]:.4g} 1/s")
