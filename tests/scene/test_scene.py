"""Scene loading and validation: every bad input of SPEC section 8 gets one clear error."""

import math

import pytest

from fxflex.errors import SceneError
from fxflex.scene import Drive, Scene, load_scene


def test_defaults_are_the_paper_scene():
    s = load_scene()
    assert s.geometry.root_y == 0.12 and s.geometry.root_z == 0.06
    assert s.geometry.twist_deg == -45.0 and s.mesh.solid == (100, 12, 6)
    assert s.load.line_load == -8000.0 and s.load.ramp_time == 300e-6
    assert s.reduction.ffrf_modes == 30 and s.reduction.gcms_modes == 90
    assert math.isclose(s.rotation.omega, 1000 * 2 * math.pi / 60)


def test_toml_file_and_overrides(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text("[geometry]\ntwist_deg = 0\nhub_radius = 0.5\n[rotation]\nrpm = 5000\n"
                 "[mesh]\nsolid = [20, 4, 2]\n")
    s = load_scene(f, ["rotation.rpm=10000", "damping.model=absolute", "load.tip_force=[0,0,-5]"])
    assert s.geometry.twist_deg == 0.0 and s.geometry.hub_radius == 0.5
    assert s.rotation.rpm == 10000.0 and s.damping.model == "absolute"
    assert s.mesh.solid == (20, 4, 2) and s.load.tip_force == (0.0, 0.0, -5.0)


def test_hash_is_stable_and_sensitive():
    a, b = load_scene(), load_scene()
    assert a.hash == b.hash and len(a.hash) == 16
    assert load_scene(overrides=["geometry.twist_deg=-45.0"]).hash == a.hash
    assert load_scene(overrides=["geometry.twist_deg=-44"]).hash != a.hash
    d = a.to_dict()
    assert d["mesh"]["solid"] == [100, 12, 6] and d["section"]["torsion"] == "polar"


@pytest.mark.parametrize("override, key, words", [
    ("geometry.lenght=2", "geometry.lenght", "unknown key"),
    ("geometri.length=2", "geometri", "unknown section"),
    ("geometry.length=\"long\"", "geometry.length", "expected a number"),
    ("mesh.beam_elements=2.5", "mesh.beam_elements", "expected an integer"),
    ("mesh.solid=[10,4]", "mesh.solid", "list of 3"),
    ("geometry.length=0", "geometry.length", "allowed: [1e-06, 1e+06]"),
    ("geometry.tip_z=-0.01", "geometry.tip_z", "allowed: (0, 1e+06]"),
    ("material.E=-1", "material.E", "> 0"),
    ("mesh.solid=[10,3,2]", "mesh.solid", "even"),
    ("mesh.solid=[10,4,1]", "mesh.solid", "even"),
    ("mesh.solid=[0,4,2]", "mesh.solid", "> 0"),
    ("material.nu=0.5", "material.nu", "(-1, 0.5)"),
    ("material.nu=-1", "material.nu", "(-1, 0.5)"),
    ("rotation.rpm=-1", "rotation.rpm", ">= 0"),
    ("rotation.profile=\"spin-up\"", "rotation.spinup_time", "> 0"),
    ("rotation.profile=fast", "rotation.profile", "allowed: constant, spin-up"),
    ("damping.model=viscous", "damping.model", "allowed: relative, absolute"),
    ("section.torsion=warping", "section.torsion", "polar, saint-venant"),
    ("mesh.ancf_root=half", "mesh.ancf_root", "free-axial, full"),
    ("damping.c=-5", "damping.c", ">= 0"),
    ("reduction.gcms_gram_tol=2", "reduction.gcms_gram_tol", "(0, 1)"),
    ("geometry.length=nan", "geometry.length", "finite"),
    ("nodots=1", "nodots", "dotted key"),
    # huge, tiny and non-finite values: the key and the allowed range (issue 11)
    ("rotation.rpm=1e300", "rotation.rpm", "allowed: below 6.985e+04 rpm"),
    ("rotation.rpm=nan", "rotation.rpm", "finite"),
    ("rotation.rpm=inf", "rotation.rpm", "finite"),
    ("geometry.twist_deg=1e300", "geometry.twist_deg", "allowed: |twist_deg| <= 854.1"),
    ("geometry.twist_deg=-855", "geometry.twist_deg", "allowed: |twist_deg| <= 854.1"),
    ("geometry.hub_radius=1e300", "geometry.hub_radius", "allowed: [0, 1e+06]"),
    ("geometry.length=1e200", "geometry.length", "allowed: [1e-06, 1e+06]"),
    ("geometry.length=5e-324", "geometry.length", "allowed: [1e-06, 1e+06]"),
    ("geometry.length=" + "9" * 400, "geometry.length", "finite"),
    ("geometry.root_y=1e7", "geometry.root_y", "allowed: (0, 1e+06]"),
    ("material.E=1e308", "material.E", "allowed: below 7.055e+20 Pa"),
    ("load.tip_force=[0,0,1e308]", "load.tip_force", "allowed: loads whose bending stress"),
    ("load.line_load=-1e12", "load.line_load", "allowed: load.line_load at most 6.05e-05 times"),
    ("damping.c=-0.0001", "damping.c", "allowed: >= 0"),
    ("damping.c=1e999", "damping.c", "finite"),
])
def test_bad_values_name_the_key(override, key, words):
    with pytest.raises(SceneError) as exc:
        load_scene(overrides=[override])
    message = str(exc.value)
    assert exc.value.key == key and message.startswith(key) and words in message
    assert "\n" not in message


def test_missing_and_invalid_files(tmp_path):
    with pytest.raises(SceneError, match="file not found"):
        load_scene(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[geometry\nlength = 1")
    with pytest.raises(SceneError, match="not valid TOML"):
        load_scene(bad)


def test_spinup_profile_is_smooth_and_consistent():
    s = load_scene(overrides=["rotation.profile=\"spin-up\"", "rotation.spinup_time=0.05"])
    d = Drive(s.rotation)
    assert d.angle(0) == 0 and d.rate(0) == 0 and d.accel(0) == 0
    h = 1e-7
    for t in (0.01, 0.03, 0.049, 0.07):
        assert d.rate(t) == pytest.approx((d.angle(t + h) - d.angle(t - h)) / (2 * h), rel=1e-6)
        assert d.accel(t) == pytest.approx((d.rate(t + h) - d.rate(t - h)) / (2 * h),
                                           rel=1e-5, abs=1e-3)
    assert d.rate(0.05) == pytest.approx(s.rotation.omega) and d.accel(0.06) == 0.0
    assert d.angle(0.06) == pytest.approx(s.rotation.omega * (0.025 + 0.01))


def test_hash_covers_the_bytes_of_named_files(tmp_path):
    """An edited stations table is another blade: the scene hash and the stored reference's key
    change with the file's bytes, not only with its path."""
    from fxflex.analysis.reference import reference_key

    csv = tmp_path / "stations.csv"
    csv.write_text("x,size_y,size_z,twist_deg\n0,0.08,0.02,0\n1,0.04,0.012,-30\n")
    before = Scene().replace(**{"geometry.stations": str(csv)})
    hashes = before.hash, reference_key(before)
    csv.write_text("x,size_y,size_z,twist_deg\n0,0.08,0.02,0\n1,0.04,0.012,-20\n")
    after = Scene().replace(**{"geometry.stations": str(csv)})
    assert after.hash != hashes[0] and reference_key(after) != hashes[1]
    assert Scene().replace(**{"geometry.stations": str(csv)}).hash == after.hash
    assert Scene().file_digests() == {} and Scene().hash == "676c6aa68814bf37"
