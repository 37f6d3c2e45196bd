"""Model files: initial velocities (``[initial_velocities]``) made consistent by velocity analysis
with the given ones held, and an assembly at t = 0 that fails because of a driver's value names
that driver, not a segment."""

from __future__ import annotations

import math

import numpy as np
import pytest

import cmbs
from cmbs.errors import ModelError

PENDULUM = """
[points]
O = { x = 0.0, z = 0.0, fixed = true }
P = { x = 0.6, z = -0.8 }

[segments.rod]
points = ["O", "P"]
mass = 1.0
com = [0.5, 0.0]
inertia = 0.08

[angles.theta]
segment = "rod"
"""

SLIDER_CRANK = """
[points]
O = { x = 0.0, z = 0.0, fixed = true }
A = { x = 0.3, z = 0.4 }
B = { x = 1.5, z = 0.0, mass = 0.5 }

[segments.crank]
points = ["O", "A"]
mass = 1.0
com = [0.25, 0.0]
inertia = 0.02

[segments.rod]
points = ["A", "B"]
mass = 2.0
com = [0.6, 0.0]
inertia = 0.25

[sliders.rail]
point = "B"
through = [0.0, 0.0]
direction = [1.0, 0.0]

[angles.phi]
segment = "crank"
"""

# crank 0.5, coupler 2, rocker 1 on a 2 m base: the rocker angle psi (D -> B) cannot be 0, which
# would put B 3 m from O, beyond crank + coupler = 2.5 m
FOUR_BAR = """
[points]
O = { x = 0.0, z = 0.0, fixed = true }
D = { x = 2.0, z = 0.0, fixed = true }
A = { x = 0.0, z = 0.5 }
B = { x = 1.6, z = 0.92 }

[segments.crank]
points = ["O", "A"]
mass = 1.0
com = [0.25, 0.0]
inertia = 0.02

[segments.coupler]
points = ["A", "B"]
mass = 1.0
com = [1.0, 0.0]
inertia = 0.3

[segments.rocker]
points = ["D", "B"]
mass = 1.0
com = [0.5, 0.0]
inertia = 0.08

[angles.psi]
segment = "rocker"

[drivers.swing]
coordinate = "psi"
expression = "0.2*t"
"""


def load(tmp_path, text, name="m.toml"):
    path = tmp_path / name
    path.write_text(text)
    return cmbs.load(path)


def test_a_given_angular_velocity_sets_the_point_velocities(tmp_path):
    """θ̇ = 2 rad/s given: P moves at ω × r = 2 (0.8, 0.6) (rod 1 m from O at (0.6, -0.8))."""
    model = load(tmp_path, PENDULUM + "\n[initial_velocities]\ntheta = 2.0\n")
    qd = dict(zip(model.coordinate_names, model.qd0))
    assert qd["theta"] == 2.0
    assert qd["P.x"] == pytest.approx(1.6, abs=1e-12) and qd["P.z"] == pytest.approx(1.2, abs=1e-12)


def test_a_given_point_velocity_sets_the_angular_velocity(tmp_path):
    """P.x velocity 1.6 given: the others follow, θ̇ = 2 and Ṗz = 1.2 (P.x held exactly)."""
    model = load(tmp_path, PENDULUM + '\n[initial_velocities]\n"P.x" = 1.6\n')
    qd = dict(zip(model.coordinate_names, model.qd0))
    assert qd["P.x"] == 1.6
    assert qd["theta"] == pytest.approx(2.0, abs=1e-12) and qd["P.z"] == pytest.approx(1.2, abs=1e-12)


def test_a_driven_start_keeps_the_drivers_rate(tmp_path):
    model = load(tmp_path, FOUR_BAR.replace('"0.2*t"', '"2.4 + 0.2*t"'))
    assert model.qd0[model.coordinate_index("psi")] == pytest.approx(0.2, abs=1e-12)


@pytest.mark.parametrize("velocities, message", [
    ('theta = 2.0\n"P.x" = 0.0', r"initial_velocities: the given velocities \(theta = 2, P.x = 0\) violate the velocity constraints at "
                                 r"t = 0 \(residual [0-9.e-]+ in constraint '(rigid rod|angle theta)'\)"),
    ("thetta = 1.0", r"initial_velocities.thetta: unknown coordinate 'thetta' \(did you mean 'theta'\?\)"),
    ('theta = "fast"', r"initial_velocities.theta: the velocity must be a finite number, got 'fast'"),
])
def test_impossible_or_misspelt_initial_velocities_are_named(tmp_path, velocities, message):
    with pytest.raises(ModelError, match=r"m.toml: " + message):
        load(tmp_path, PENDULUM + "\n[initial_velocities]\n" + velocities + "\n")


def test_a_velocity_against_a_driver_names_the_driver(tmp_path):
    text = FOUR_BAR.replace('"0.2*t"', '"2.4 + 0.2*t"') + "\n[initial_velocities]\npsi = 1.0\n"
    with pytest.raises(ModelError, match=r"initial_velocities: .*in driver 'swing'"):
        load(tmp_path, text)


def test_a_driver_value_out_of_reach_is_named_not_a_segment(tmp_path):
    """ψ(0) = 0 puts B 3 m from O (crank + coupler: 2.5 m): the driver is at fault, and the
    mechanism itself closes (the same file with ψ(0) = 2.4 loads)."""
    assert load(tmp_path, FOUR_BAR.replace('"0.2*t"', '"2.4 + 0.2*t"'), "ok.toml").m == 5
    with pytest.raises(ModelError) as caught:
        load(tmp_path, FOUR_BAR)
    error = caught.value
    assert error.entry == "drivers.swing"
    assert "drivers.swing holds psi at 0 at t = 0, which the mechanism cannot reach" in str(error)


def test_a_slider_position_beyond_reach_names_its_driver(tmp_path):
    text = SLIDER_CRANK + '\n[drivers.slide]\ncoordinate = "B.x"\nexpression = "2.5 - 0.1*t"\n'
    with pytest.raises(ModelError) as caught:
        load(tmp_path, text)
    assert caught.value.entry == "drivers.slide"
    assert "holds B.x at 2.5 at t = 0" in str(caught.value)


def test_cli_names_the_driver_in_one_line(tmp_path, capsys):
    from cmbs.cli import main

    path = tmp_path / "m.toml"
    path.write_text(FOUR_BAR)
    assert main(["describe", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "drivers.swing" in err[0]
