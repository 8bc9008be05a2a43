# %% [markdown]
# # fxflex from Python: scene, build, steady state, run, modes, Campbell
#
# Everything here comes from `import fxflex` (docs/api.md). The beam methods build in
# milliseconds, so the demo takes seconds; a solid method is the same calls with
# `fxflex.build("tlf", scene)` (and dolfinx underneath).

# %%
import math
import os
import tempfile

import fxflex

# The paper's scene (SPEC section 1) with keys replaced as `--set` does on the command line.
scene = fxflex.load_scene(overrides=["rotation.rpm=5000"])
print(f"scene {scene.hash}: {scene.rotation.rpm:g} rpm, c = {scene.damping.c:g}, "
      f"{scene.mesh.beam_elements} beam elements")

# A bad value is refused when the scene is made, with the line the CLI prints.
try:
    fxflex.scene_from_dict({"material": {"nu": 0.5}})
except fxflex.SceneError as exc:
    print("refused:", exc)

# %% Equilibrium in the rotating frame (SPEC section 6) and its stability
form = fxflex.build("nebb", scene)
st = fxflex.steady(form)
stable, note = fxflex.stability(form, st)
print(f"NEBB at 5000 rpm: tip {1e3 * st.tip} mm, {st.iterations} Newton iterations, "
      f"stable {stable}")

# %% A transient with the paper's integrator and step, its series written as `--out` writes it
with tempfile.TemporaryDirectory() as folder:
    path = os.path.join(folder, "nebb.csv")
    result = fxflex.run(form, t_end=1e-3, out=path, sample_dt=1e-5)
    with open(path) as fh:
        rows = [line for line in fh if not line.startswith("#")]
print(f"run: {result.steps} steps to t = {result.t:g} s in {result.wall_s:.2f} s, "
      f"tip {1e3 * result.tip} mm; {len(rows) - 1} samples written")
assert result.diverged is None and len(rows) - 1 == 101

# %% The linear floating-frame beam loses stability at the paper's highest speed (Sect. 4.1)
lebb = {rpm: fxflex.build("lebb", scene.replace(**{"rotation.rpm": rpm}))
        for rpm in fxflex.PAPER_RPM}
verdicts = {rpm: fxflex.stability(f)[0] for rpm, f in lebb.items()}
print("LEBB equilibrium stable:", verdicts)
assert verdicts[1000.0] and not verdicts[10000.0]

# %% Modes of a slender uniform untwisted beam at rest against Euler-Bernoulli's cantilever
# (10 m long: the beam's rotary inertia, which Euler-Bernoulli leaves out, then lowers the
# frequency by about 1e-5 instead of the 7e-4 it costs the 1 m beam)
straight = scene.replace(**{"geometry.length": 10.0, "geometry.tip_y": scene.geometry.root_y,
                            "geometry.tip_z": scene.geometry.root_z, "geometry.twist_deg": 0.0,
                            "rotation.rpm": 0.0, "damping.c": 0.0, "load.line_load": 0.0})
modes = fxflex.modes(fxflex.build("lebb", straight), 4)
for f, label in zip(modes.frequencies_hz, modes.labels):
    print(f"  {f:9.4f} Hz  {label}")
g, mat = straight.geometry, straight.material
b, h = g.root_y, g.root_z
# first bending mode across the thin side (along Z): (beta L)^2 sqrt(E I / (rho A L^4)) / 2 pi
f1 = 1.8751040687**2 / (2 * math.pi) * math.sqrt(mat.E * b * h**3 / 12
                                                  / (mat.rho * b * h * g.length**4))

# %% Campbell: von Karman strain (NEBB) carries the centrifugal stiffening, so its lowest
# frequency rises with the speed; the linear beam (LEBB) has only the spin softening, its in-plane
# mode drops to zero and the equilibrium turns unstable (the shaded range of `--campbell`)
speeds = [0.0, 2500.0, 5000.0, 10000.0]
for method in ("nebb", "lebb"):
    data = fxflex.campbell(method, speeds, n=2)
    lowest = [m.frequencies_hz[0] for m in data.modes]
    print(f"{method} lowest frequency (Hz) at {speeds} rpm:", [f"{f:.2f}" for f in lowest],
          "unstable:", data.unstable_ranges() or "nowhere")
    if method == "nebb":
        assert all(a < b for a, b in zip(lowest, lowest[1:])) and not data.unstable_ranges()
    else:
        assert lowest[2] < lowest[0] and data.unstable_ranges()[-1][1] == speeds[-1]

# %% the checked value
error = modes.frequencies_hz[0] / f1 - 1
assert modes.labels[0] == "out-of-plane" and abs(error) < 1e-4, error
print(f"checked: lowest LEBB frequency {modes.frequencies_hz[0]:.4f} Hz, Euler-Bernoulli "
      f"{f1:.4f} Hz (relative error {error:.1e})")
