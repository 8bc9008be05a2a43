# %% [markdown]
# # A beam at rest: LEBB, NEBB and ANCF against q L^4 / (8 E I)
#
# A uniform, untwisted 0.12 x 0.06 m steel cantilever, 1 m long, under a line load along z and
# no rotation. Cubic Hermite elements with consistent loads are nodally exact, so LEBB gives the
# Euler-Bernoulli tip deflection to round-off; NEBB agrees in this linear range; ANCF is a 3D
# continuum beam: with nu = 0 it is Timoshenko's beam (slightly softer), with nu = 0.28 the
# linear interpolation of its section gradients along X makes it a little stiffer (locking).

# %%
from fxflex.formulation import build
from fxflex.scene import Scene

scene = Scene().replace(**{"geometry.tip_y": 0.12, "geometry.tip_z": 0.06,
                           "geometry.twist_deg": 0.0, "rotation.rpm": 0.0,
                           "load.line_load": -800.0})
E, L, q = scene.material.E, scene.geometry.length, scene.load.line_load
I = scene.geometry.root_y * scene.geometry.root_z**3 / 12
reference = q * L**4 / (8 * E * I)

# %%
for method, sc in (("lebb", scene), ("nebb", scene), ("ancf", scene),
                   ("ancf", scene.replace(**{"material.nu": 0.0}))):
    tip = build(method, sc, None).steady_state().tip[2]
    print(f"{method} (nu = {sc.material.nu:g}): tip {1e3 * tip:+.6f} mm, "
          f"ratio to q L^4 / 8 E I = {tip / reference:.6f}")

# %% the checked value
ratio = build("lebb", scene, None).steady_state().tip[2] / reference
assert abs(ratio - 1) < 1e-10
print(f"LEBB nodal exactness: {ratio:.12f}")
