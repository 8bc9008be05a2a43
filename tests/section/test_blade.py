"""The section keys of SPEC section 9 (fxflex.section.blade) and `fxflex section`."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from fxflex.errors import SceneError
from fxflex.scene import Scene, load_scene
from fxflex.section.blade import Blade, section_table

pytestmark = pytest.mark.serial


def _scene(*sets):
    return load_scene(None, list(sets))


def test_paper_scene_unchanged():
    """The new keys at their defaults leave the scene hash as before them (checkpoints resume)
    and the paper's rectangle is what the blade gives."""
    assert Scene().hash == "676c6aa68814bf37"
    blade = Blade(Scene().geometry)
    assert blade.outline(0.0).extent == pytest.approx((0.12, 0.06))
    assert blade.outline(1.0).extent == pytest.approx((0.08, 0.04))


def test_stations_table(tmp_path):
    """Sizes, twist and wall linear between the table's rows; the rows are the default
    stations; the properties follow (a rectangle's A = b h exactly)."""
    f = tmp_path / "st.csv"
    f.write_text("x,size_y,size_z,twist_deg,wall\n0,0.2,0.1,0,0.01\n0.5,0.1,0.05,10,0.005\n"
                 "1.0,0.1,0.05,20,0.005\n")
    s = _scene(f"geometry.stations={json.dumps(str(f))}")
    blade = Blade(s.geometry)
    by, bz, tw, wall = blade.sizes(0.25)
    assert (by, bz, math.degrees(tw), wall) == pytest.approx((0.15, 0.075, 5.0, 0.0075))
    rows = section_table(s)
    assert [r["x"] for r in rows] == [0.0, 0.5, 1.0]
    assert rows[0]["A"] == pytest.approx(0.2 * 0.1 - 0.18 * 0.08, rel=1e-12)
    assert rows[1]["twist_deg"] == pytest.approx(10.0)
    assert rows[0]["mass_per_length"] == pytest.approx(7850.0 * rows[0]["A"])


@pytest.mark.parametrize("text, what", [
    ("x,size_y\n0,1\n", "header"),
    ("x,size_y,size_z,twist_deg\n0,0.1,0.05,0\n", "two or more"),
    ("x,size_y,size_z,twist_deg\n0,0.1,0.05,0\n0.5,0.1,0.05,0\n", "from 0 to geometry.length"),
    ("x,size_y,size_z,twist_deg\n0,0.1,0.05,0\n0.6,0.1,0.05,0\n0.4,0.1,0.05,0\n1,0.1,0.05,0\n",
     "not increasing"),
    ("x,size_y,size_z,twist_deg\n0,0.1,0.05,0\n1,0,0.05,0\n", "above 0"),
    ("x,size_y,size_z,twist_deg\n0,0.1,abc,0\n1,0.1,0.05,0\n", "line 2"),
])
def test_stations_refused(tmp_path, text, what):
    f = tmp_path / "st.csv"
    f.write_text(text)
    with pytest.raises(SceneError, match=f"geometry.stations: .*{what}"):
        _scene(f"geometry.stations={json.dumps(str(f))}")


def test_contour_file(tmp_path):
    """A polygon contour with a hole, scaled along the span by the sizes; refusals name the
    key: no file, a bowtie, a contour without section = polygon."""
    f = tmp_path / "c.csv"
    f.write_text("y,z\n0,0\n0.12,0\n0.12,0.06\n0,0.06\n\n0.02,0.02\n0.1,0.02\n0.1,0.04\n"
                 "0.02,0.04\n")
    s = _scene("geometry.section=polygon", f"geometry.contour={json.dumps(str(f))}")
    rows = section_table(s, 2)
    assert rows[0]["A"] == pytest.approx(0.12 * 0.06 - 0.08 * 0.02, rel=1e-12)
    assert rows[1]["A"] == pytest.approx(rows[0]["A"] * (0.08 / 0.12) * (0.04 / 0.06), rel=1e-12)
    assert rows[0]["centroid"] == pytest.approx([0.06, 0.03], rel=1e-9)
    with pytest.raises(SceneError, match="geometry.contour: file not found"):
        _scene("geometry.section=polygon", "geometry.contour=nowhere.csv")
    f.write_text("0,0\n1,1\n1,0\n0,1\n")
    with pytest.raises(SceneError, match="geometry.contour: .*crosses itself"):
        _scene("geometry.section=polygon", f"geometry.contour={json.dumps(str(f))}")
    with pytest.raises(SceneError, match="geometry.contour: given with"):
        _scene(f"geometry.contour={json.dumps(str(f))}")


def test_naca_keys():
    """The airfoil accepted as TOML's integer (0012 reads as 12); bad digits and a Z size that
    disagrees with the thickness are refused; a wall too thick for the section is refused."""
    assert _scene("geometry.section=naca4", "geometry.airfoil=0012").geometry.airfoil == "0012"
    with pytest.raises(SceneError, match="geometry.airfoil"):
        _scene("geometry.section=naca4", "geometry.airfoil=12345")
    with pytest.raises(SceneError, match="geometry.root_z: .*0.0144"):
        _scene("geometry.section=naca4", "geometry.root_z=0.02")
    assert _scene("geometry.section=naca4", "geometry.root_z=0.0144").geometry.root_z == 0.0144
    with pytest.raises(SceneError, match="geometry.wall: .*leaves no hollow"):
        _scene("geometry.section=ellipse", "geometry.wall=0.05")
    with pytest.raises(SceneError, match="geometry.section: .*allowed: rectangle, ellipse"):
        _scene("geometry.section=circle")


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "fxflex", "section", *args],
                          capture_output=True, text=True, timeout=300)


def test_cli_section(tmp_path):
    """Text and JSON (SPEC section 9 names) and the plots; a bad option is one line, exit 2,
    nothing written."""
    r = _cli("--set", "geometry.section=naca4", "--set", "geometry.airfoil=2412", "--stations",
             "2", "--json", "--plot", str(tmp_path / "p"))
    assert r.returncode == 0, r.stderr
    data = json.loads(r.stdout)
    st = data["stations"]
    assert [s["x"] for s in st] == [0.0, 1.0]
    for key in ("A", "centroid", "Iy", "Iz", "Iyz", "principal_deg", "J", "shear_centre",
                "mass_per_length"):
        assert key in st[0]
    assert st[1]["A"] == pytest.approx(st[0]["A"] * (0.08 / 0.12) ** 2, rel=1e-3)
    assert sorted(p.name for p in (tmp_path / "p").iterdir()) == [
        "blade.png", "section_00.png", "section_01.png"]
    r = _cli("--stations", "3")
    assert r.returncode == 0 and len(r.stdout.strip().splitlines()) == 5
    r = _cli("--resolution", "2", "--plot", str(tmp_path / "q"))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "--resolution" in r.stderr and not (tmp_path / "q").exists()
    r = _cli("--set", "geometry.section=naca4", "--set", "geometry.airfoil=2400")
    assert r.returncode == 2 and "geometry.airfoil" in r.stderr
