"""[tip_mass] (SPEC section 10, issue 16): the scene table and its checks."""

import pytest

from fxflex.errors import SceneError
from fxflex.scene import Scene, load_scene
from fxflex.scene.load import TIP_MASS_METHODS, validate_for


def test_tip_mass_table_reads_and_its_defaults_leave_the_hash():
    plain = load_scene()
    zero = load_scene(overrides=["tip_mass.mass=0", "tip_mass.inertia=[0, 0, 0]"])
    assert "tip_mass" not in plain.stable_dict() and zero.hash == plain.hash
    heavy = load_scene(overrides=["tip_mass.mass=2.5", "tip_mass.inertia=[0.2, 0.1, 0.1]"])
    assert heavy.tip_mass.mass == 2.5 and heavy.tip_mass.inertia == (0.2, 0.1, 0.1)
    assert heavy.stable_dict()["tip_mass"] == {"mass": 2.5, "inertia": [0.2, 0.1, 0.1]}
    assert heavy.hash != plain.hash
    # Pi = tr(J)/2 I - J: J_X = Pi_YY + Pi_ZZ etc.
    pi = heavy.tip_mass.second_moments().diagonal()
    assert list(pi) == pytest.approx([0.0, 0.1, 0.1], abs=1e-15)


@pytest.mark.parametrize("override, words", [
    ("tip_mass.mass=-1", "allowed: >= 0"),
    ("tip_mass.inertia=[0.1, -0.1, 0.1]", "allowed: >= 0"),
    ("tip_mass.inertia=[0.1, 0.1]", "list of 3"),
    ("tip_mass.inertia=[1, 0, 0]", "at most the sum of the other two"),
    ("tip_mass.mass=1e9", "meaningless for an elastic body"),
    ("tip_mass.radius=1", "unknown key"),
])
def test_bad_tip_mass_is_one_line_naming_the_key(override, words):
    with pytest.raises(SceneError) as err:
        load_scene(overrides=[override, "rotation.rpm=10000"])
    text = str(err.value)
    assert text.startswith("tip_mass.") and words in text and "\n" not in text


@pytest.mark.parametrize("method", ["ffrf", "gcms", "tlf", "lebb", "nebb", "ancf"])
def test_methods_without_a_tip_mass_refuse_one(method):
    scene = Scene().replace(**{"tip_mass.mass": 1.0})
    validate_for(method, Scene())
    if method in TIP_MASS_METHODS:
        validate_for(method, scene)
    else:
        with pytest.raises(SceneError, match="tip_mass: .* allowed: mass and inertia 0"):
            validate_for(method, scene)
