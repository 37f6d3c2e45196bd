"""Independent numerical checks shared by the tests: finite differences of the model's own
position-level functions, against which the analytic A, γ, Φ_t and Q are compared; and where the
robot tests find their URDF files."""

from __future__ import annotations

import importlib.metadata
from pathlib import Path

import numpy as np


def example_robots() -> Path | None:
    """example-robot-data's robots directory (the URDF files the robot tests load), None when the
    package (the [test] extra) is not installed."""
    try:
        distribution = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return None
    path = Path(str(distribution.locate_file("cmeel.prefix/share/example-robot-data/robots")))
    return path if path.is_dir() else None


def jacobian_fd(model, q: np.ndarray, t: float = 0.0, h: float = 1e-6) -> np.ndarray:
    """Central-difference Φ_q (error O(h²))."""
    columns = []
    for k in range(model.n):
        step = np.zeros(model.n)
        step[k] = h
        columns.append((model.constraints(q + step, t) - model.constraints(q - step, t)) / (2 * h))
    return np.array(columns).T


class SmoothPath:
    """q(t) = c + a sin(w t + p) per coordinate, with exact q̇ and q̈ (a random smooth motion)."""

    def __init__(self, center: np.ndarray, rng: np.random.Generator, amplitude: float = 0.3):
        n = center.size
        self.c = center
        self.a = amplitude * rng.uniform(0.2, 1.0, n)
        self.w = rng.uniform(0.5, 2.0, n)
        self.p = rng.uniform(0, 2 * np.pi, n)

    def q(self, t: float) -> np.ndarray:
        return self.c + self.a * np.sin(self.w * t + self.p)

    def qd(self, t: float) -> np.ndarray:
        return self.a * self.w * np.cos(self.w * t + self.p)

    def qdd(self, t: float) -> np.ndarray:
        return -self.a * self.w**2 * np.sin(self.w * t + self.p)


def second_derivative_fd(function, t: float, h: float = 1e-3) -> np.ndarray:
    """Five-point central second derivative (error O(h⁴))."""
    f = [np.asarray(function(t + k * h)) for k in (-2, -1, 0, 1, 2)]
    return (-f[0] + 16 * f[1] - 30 * f[2] + 16 * f[3] - f[4]) / (12 * h * h)


def first_derivative_fd(function, t: float, h: float = 1e-4) -> np.ndarray:
    """Four-point central first derivative (error O(h⁴))."""
    f = [np.asarray(function(t + k * h)) for k in (-2, -1, 1, 2)]
    return (f[0] - 8 * f[1] + 8 * f[2] - f[3]) / (12 * h)


def check_constraint_derivatives(model, rng: np.random.Generator, *, samples: int = 3, amplitude: float = 0.3,
                                 rtol: float = 1e-6) -> None:
    """Assert A = FD(Φ), Φ_t = FD_t(Φ) and γ = A q̈ - d²Φ/dt² along random smooth motions."""
    for _ in range(samples):
        path = SmoothPath(np.asarray(model.q0, float), rng, amplitude)
        t = float(rng.uniform(0.0, 2.0))
        q, qd, qdd = path.q(t), path.qd(t), path.qdd(t)
        A = model.jacobian(q, t)
        A_fd = jacobian_fd(model, q, t)
        scale_A = max(1.0, np.abs(A).max(initial=0.0))
        np.testing.assert_allclose(A, A_fd, atol=1e-7 * scale_A, rtol=0)

        phi_t_fd = first_derivative_fd(lambda s: model.constraints(q, s), t)
        np.testing.assert_allclose(model.constraints_t(q, t), phi_t_fd, atol=1e-7 * scale_A, rtol=0)

        phi_dd = second_derivative_fd(lambda s: model.constraints(path.q(s), s), t)
        gamma_expected = A @ qdd - phi_dd
        gamma = model.gamma(q, qd, t)
        scale = max(1.0, np.abs(gamma_expected).max(initial=0.0), np.abs(A @ qdd).max(initial=0.0))
        np.testing.assert_allclose(gamma, gamma_expected, atol=rtol * scale, rtol=0)


def kitchen_sink(*, drivers: bool = True, loads: bool = True, python_driver: bool = True):
    """A natural-coordinate model using every entry kind (the same model as
    tests/data/kitchen-sink.toml): crank-rod-block on a ground slider with rotation lock, a
    distance coordinate, absolute/relative/point-pair angles, a pendulum sliding on the rod (a
    body with a third point H), a point sliding on the crank line, a spring-damper, a
    time-varying point force, a follower force on the rod, a torque, a moment on the crank,
    an actuator and drivers from an expression, a table and a Python callable.

    ``python_driver=False`` gives the F.x driver as the expression ``0.4 + 0.05*sin(t)`` instead
    of the Python callable (named "f-drive"): exactly the model of tests/data/kitchen-sink.toml."""
    import math

    from cmbs.model.drivers import PythonFunction, Table
    from cmbs.model.natural import NaturalModelBuilder

    b = NaturalModelBuilder("kitchen-sink", gravity=(0.0, -9.81))
    b.add_point("O", 0.0, 0.0, fixed=True)
    b.add_point("A", 0.8, 0.6)
    b.add_point("B", 2.0, 0.5)
    b.add_point("Bb", 2.3, 0.5)
    b.add_point("D", 1.4, 0.55)
    b.add_point("E", 1.45, -0.3)
    b.add_point("F", 0.4, 0.3, mass=0.5)
    b.add_point("H", 1.7, -0.2)
    b.add_segment("crank", "O", "A", mass=1.0, com=(0.5, 0.05), inertia=0.1)
    b.add_segment("rod", "A", "B", mass=2.0, com=(0.6, -0.02), inertia=0.2)
    b.add_segment("block", "B", "Bb", mass=0.7, com=(0.15, 0.0), inertia=0.01)
    b.add_body("hanger", ["D", "E", "H"], mass=0.4, com=(0.3, 0.1), inertia=0.02)
    b.add_slider("ground", point="B", through=(0.0, 0.5), direction=(1.0, 0.0), lock="block")
    b.add_slider("on-rod", point="D", segment="rod")
    b.add_slider("on-crank", point="F", line=("O", "A"))
    b.add_distance("s", "O", "B")
    b.add_angle("phi", segment="crank")
    b.add_angle("psi", from_segment="crank", to_segment="rod")
    b.add_angle("chi", from_segment=("O", "B"), to_segment=("D", "E"))
    if loads:
        b.add_spring("spring", "A", "E", stiffness=50.0, damping=2.0, rest_length=0.9)
        b.add_force("push", point="E", fx="0.5*cos(t)", fz=-1.0)
        b.add_torque("motor", angle="psi", torque="2*sin(3*t)")
        b.add_force("follower", segment="rod", at=(0.9, 0.05), frame="body", fx="0.3*sin(t)", fz="0.2*sin(2*t)")
        b.add_moment("twist", segment="crank", moment="0.4*sin(t)")
    b.add_actuator("tau", coordinate="phi", gain=1.5)
    b.add_actuator("f", coordinate="s")
    if drivers:
        b.add_driver("phi", "0.6435 + 0.2*sin(t)", name="crank-drive")
        b.add_driver("D.x", Table(np.linspace(0, 3, 16), 1.4 + 0.1 * np.sin(np.linspace(0, 3, 16))),
                     name="table-drive")
        if python_driver:
            b.add_driver("F.x", PythonFunction(lambda t: 0.4 + 0.05 * math.sin(t), lambda t: 0.05 * math.cos(t),
                                               lambda t: -0.05 * math.sin(t)), name="python-drive")
        else:
            b.add_driver("F.x", "0.4 + 0.05*sin(t)", name="f-drive")
    return b.build()


def library_four_bar_variant(name: str, *, coupler_mass: float = 5.0, coupler_com: tuple = (5.0, 0.0),
                             driver: object | None = None, actuator: bool = False):
    """The library four-bar rebuilt with the builder (same points and bars), optionally with another
    coupler mass (inertia scaled with it) or COM, a driver on alpha, or a torque actuator."""
    import cmbs

    base = cmbs.load("four-bar")
    b = cmbs.NaturalModelBuilder(name)
    b.add_point("A", 0.0, 0.0, fixed=True)
    b.add_point("B", 10.0, 0.0, fixed=True)
    b.add_point("P1", *base.q0[0:2])
    b.add_point("P2", *base.q0[2:4])
    b.add_segment("crank", "A", "P1", mass=1.0, com=(1.0, 0.0), inertia=1 / 3, length=2.0)
    b.add_segment("coupler", "P1", "P2", mass=coupler_mass, com=coupler_com, inertia=coupler_mass * 100 / 12,
                  length=10.0)
    b.add_segment("rocker", "P2", "B", mass=3.0, com=(3.0, 0.0), inertia=9.0, length=6.0)
    b.add_angle("alpha", segment="crank")
    if driver is not None:
        b.add_driver("alpha", driver)
    if actuator:
        b.add_actuator("torque", coordinate="alpha")
    return b.build()


def arm_on_slider_motion():
    """The arm on a slider and a smooth motion of it for tracking tests: 1 s at 5 ms, θ2 and θ3
    oscillating about their initial values (θ2 + 0.2 sin 2t, θ3 - 0.1 sin 3t), the slider held;
    velocities and accelerations left zero (a Reference fits its own spline)."""
    import cmbs

    arm = cmbs.load("arm-on-slider")
    t = np.linspace(0.0, 1.0, 201)
    q = np.tile(arm.q0, (t.size, 1))
    q[:, 1] += 0.2 * np.sin(2 * t)
    q[:, 2] -= 0.1 * np.sin(3 * t)
    return arm, cmbs.Trajectory(t, q, np.zeros_like(q), np.zeros_like(q), arm.coordinate_names)


def four_bar_builders(revolute_bodies: bool = False):
    """Builders of the crank-rocker O-A-B-C in the plane y = 0 (planar, gravity -z) and in space
    (gravity -z): rods with spherical ends kept in the plane by two products, or bodies with
    revolute joints (each body carries the ground axis y, and a body-fixed unit vector n across
    its bar): redundant constraints."""
    from cmbs.model.natural import NaturalModelBuilder
    from cmbs.model.spatial import SpatialModelBuilder

    O, A, B, C = (0.0, 0.0), (0.0, 0.5), (1.0, 1.0), (1.0, 0.0)
    bars = {"crank": ("O", "A", 1.0), "coupler": ("A", "B", 2.0), "rocker": ("C", "B", 1.5)}
    points = {"O": O, "A": A, "B": B, "C": C}
    planar = NaturalModelBuilder("four-bar-planar", gravity=(0.0, -9.81))
    spatial = SpatialModelBuilder("four-bar-spatial", gravity=(0.0, 0.0, -9.81))
    for name, (x, z) in points.items():
        planar.add_point(name, x, z, fixed=name in "OC")
        spatial.add_point(name, (x, 0.0, z), fixed=name in "OC")
    spatial.add_vector("y", (0.0, 1.0, 0.0), fixed=True)
    for name, (i, j, mass) in bars.items():
        d = np.subtract(points[j], points[i])
        length = float(np.hypot(*d))
        inertia = mass * length**2 / 12.0
        planar.add_segment(name, i, j, mass=mass, com=(0.5 * length, 0.0), inertia=inertia)
        if not revolute_bodies:
            spatial.add_rod(name, i, j, mass=mass, com=0.5, inertia=inertia)
            continue
        along = np.array([d[0], 0.0, d[1]]) / length
        across = np.cross(along, (0.0, 1.0, 0.0))
        spatial.add_vector(f"n_{name}", across)
        rotation = np.column_stack([along, (0.0, 1.0, 0.0), across])
        middle = 0.5 * (np.array([*points[i]]) + np.array([*points[j]]))
        spatial.add_body(name, origin=i, basis=[j, "y", f"n_{name}"], mass=mass, com=(middle[0], 0.0, middle[1]),
                         inertia=rotation @ np.diag([1e-4, inertia, inertia + 1e-4]) @ rotation.T)
    if not revolute_bodies:
        spatial.add_dot("crank in plane", ("A", "O"), "y")
        spatial.add_dot("rocker in plane", ("B", "C"), "y")
    return planar, spatial
