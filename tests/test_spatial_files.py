"""Spatial model files (``[model] dimension = 3``, cmbs.model.spatial_files): the file's model is
the builder's, and every mistake is one line naming the file, the entry and the value."""

import numpy as np
import pytest

import cmbs
from cmbs.errors import ModelError

TOP = """
[model]
name = "top"
dimension = 3
gravity = [0.0, 0.0, -9.81]

[points]
O = { position = [0.0, 0.0, 0.0], fixed = true }
tip = { position = [0.0, 0.0, 0.2] }

[vectors]
u = { direction = [1.0, 0.0, 0.0] }
v = { direction = [0.0, 1.0, 0.0] }
w = { direction = [0.0, 0.0, 1.0] }

[bodies.top]
origin = "O"
basis = ["u", "v", "w"]
mass = 1.0
com = [0.0, 0.0, 0.1]
inertia = [4e-3, 4e-3, 6e-3]
points = ["tip"]

[initial_velocities]
"u.y" = 50.0
"""


def test_the_file_builds_the_model_of_the_builder(tmp_path):
    path = tmp_path / "top.toml"
    path.write_text(TOP)
    from_file = cmbs.load(path)
    builder = cmbs.SpatialModelBuilder("top")
    builder.add_point("O", (0.0, 0.0, 0.0), fixed=True)
    builder.add_point("tip", (0.0, 0.0, 0.2))
    for name, direction in (("u", (1, 0, 0)), ("v", (0, 1, 0)), ("w", (0, 0, 1))):
        builder.add_vector(name, direction)
    builder.add_body("top", origin="O", basis=["u", "v", "w"], mass=1.0, com=(0.0, 0.0, 0.1),
                     inertia=np.diag([4e-3, 4e-3, 6e-3]), points=["tip"])
    built = builder.build()
    assert from_file.coordinate_names == built.coordinate_names
    assert from_file.constraint_names == built.constraint_names
    np.testing.assert_array_equal(from_file.mass_matrix(from_file.q0), built.mass_matrix(built.q0))
    # the spin about w held: u turns towards v at 50 rad/s, v away from u
    assert from_file.qd0[from_file.coordinate_index("u.y")] == 50.0
    assert from_file.qd0[from_file.coordinate_index("v.x")] == pytest.approx(-50.0, abs=1e-12)
    assert from_file.kinetic_energy(from_file.q0, from_file.qd0) == pytest.approx(0.5 * 6e-3 * 50.0**2, rel=1e-12)


@pytest.mark.parametrize("change, entry, problem", [
    (("dimension = 3", "dimension = 4"), "model.dimension", "got 4"),
    (('basis = ["u", "v", "w"]', 'basis = ["u", "v", "ww"]'), "bodies.top", "no point or vector 'ww'"),
    (("inertia = [4e-3, 4e-3, 6e-3]", "inertia = [4e-3, 4e-3, 9e-3]"), "bodies.top", "0.004, 0.004, 0.009"),
    (("inertia = [4e-3, 4e-3, 6e-3]", 'inertia = "big"'), "bodies.top", "got 'big'"),
    (("mass = 1.0", "mas = 1.0"), "bodies.top", "unknown key(s) 'mas'"),
    (("com = [0.0, 0.0, 0.1]", "com = [0.0, 0.1]"), "bodies.top", "got [0.0, 0.1]"),
    (("[vectors]", "[vectorz]"), None, "unknown section(s) 'vectorz'"),
    (('"u.y" = 50.0', '"u.q" = 50.0'), "initial_velocities.u.q", "unknown coordinate 'u.q'"),
    (("w = { direction = [0.0, 0.0, 1.0] }", "w = { direction = [1.0, 0.0, 0.0] }"), "bodies.top", "coplanar"),
    (("w = { direction = [0.0, 0.0, 1.0] }", "w = { direction = [0.0, 0.0, 0.0] }"), "vectors.w", "not be zero"),
    (("tip = { position = [0.0, 0.0, 0.2] }", "tip = { position = [0.0, 0.0, nan] }"), "points.tip",
     "three finite numbers"),
    (("fixed = true }", "fixed = 1 }"), "points.O", "true or false, got 1"),
])
def test_a_mistake_names_the_file_the_entry_and_the_value(tmp_path, change, entry, problem):
    path = tmp_path / "top.toml"
    old, new = change
    assert old in TOP
    path.write_text(TOP.replace(old, new, 1))
    with pytest.raises(ModelError) as caught:
        cmbs.load(path)
    message = str(caught.value)
    assert message.startswith(str(path))
    if entry is not None:
        assert caught.value.entry == entry, message
    assert problem in message


def test_an_assembly_that_fails_names_an_entry_and_a_row_between_fixed_elements_is_refused(tmp_path):
    path = tmp_path / "apart.toml"
    text = """
[model]
dimension = 3
[points]
A = { position = [0.0, 0.0, 0.0], fixed = true }
B = { position = [1.0, 0.0, 0.0] }
C = { position = [5.0, 0.0, 0.0], fixed = true }
[rods]
first = { points = ["A", "B"], mass = 1.0 }
second = { points = ["B", "C"], mass = 1.0 }
"""
    path.write_text(text)                     # 1 m + 4 m reach C 5 m away: it closes, B on the line
    assert cmbs.load(path).n == 3
    path.write_text(text.replace('second = { points = ["B", "C"], mass = 1.0 }', "") + """
[distances.gap]
points = ["B", "C"]
[drivers.hold]
coordinate = "gap"
expression = "7.0"
""")                                               # B, 1 m from A, cannot be 7 m from C, 5 m away
    with pytest.raises(ModelError) as caught:
        cmbs.load(path)
    assert caught.value.entry == "drivers.hold"
    assert "cannot reach" in str(caught.value) and "gap at 7" in str(caught.value)
    path.write_text(text + '[dots.ground]\na = ["C", "A"]\nb = ["C", "A"]\n')
    with pytest.raises(ModelError, match="dots.ground: relates fixed elements only"):
        cmbs.load(path)


@pytest.mark.parametrize("extra, entry, problem", [
    ('[forces.push]\npoint = "tip"\nforce = [0.0, "sin(", 0.0]', "forces.push.force.y", "sin("),
    ('[forces.push]\npoint = "tip"\nforce = [0.0, 1.0]', "forces.push", "three components"),
    ('[forces.push]\npoint = "tip"\nforce = [1.0, 0.0, 0.0]\nbody = "topp"', "forces.push", "no body 'topp'"),
    ('[moments.turn]\nbody = "top"\nmoment = [0.0, 0.0, 1.0]\nframe = "local"', "moments.turn",
     "frame must be one of 'ground', 'body', got 'local'"),
    ('[rotational_springs.twist]\nangle = "spin"\nstiffness = 1.0', "rotational_springs.twist", "no angle 'spin'"),
    ('[rotational_springs.twist]\nangle = "spin"\nstiffness = -1.0', "rotational_springs.twist",
     "stiffness must be a finite number >= 0, got -1.0"),
    ('[sliders.s]\npoint = "tip"\norigin = "O"\naxis = "u"', "sliders.s", "'tip' is 0.2 m off the line"),
    ('[sliders.s]\npoint = "tip"\norigin = "O"\naxis = "tip"', "sliders.s", "'tip' is a point, not a vector"),
])
def test_a_mistake_in_a_load_or_a_slider_names_its_entry(tmp_path, extra, entry, problem):
    path = tmp_path / "top.toml"
    path.write_text(TOP + "\n" + extra + "\n")
    with pytest.raises(ModelError) as caught:
        cmbs.load(path)
    message = str(caught.value)
    assert message.startswith(str(path))
    assert caught.value.entry == entry, message
    assert problem in message
