"""Servo-constraint inverse dynamics of underactuated systems (Quasem, Uhlar & Betsch 2009):
the step equations hold, full and projected methods and redundant (RED) and joint (GEN)
coordinates converge to each other at first order, the inputs replayed in a forward simulation
reproduce the path, fully actuated cases match closed forms and cmbs.inverse_dynamics, and a
path that leaves the workspace stops with a message saying when and why."""

import math

import numpy as np
import pytest

import cmbs
from cmbs.errors import CmbsError
from cmbs.inverse.servo import (LinePath, ServoConvergenceError, callable_output, coordinate_output, segment_point,
                                servo_inverse_dynamics)
from cmbs.model.joints import JointModelBuilder
from cmbs.motion import prescribe, read_motion
from helpers import SmoothPath, first_derivative_fd, second_derivative_fd

RED, GEN = "passive-manipulator", "passive-manipulator-joint"
SHIFT = np.array([-2.0, -2.0])  # link-3 COM from (7.5, 5) to (5.5, 3) in 3 s (examples/passive_manipulator_servo.py)
DURATION = 3.0


def grid(dt: float, t_end: float = DURATION) -> np.ndarray:
    return np.linspace(0.0, t_end, int(round(t_end / dt)) + 1)


@pytest.fixture(scope="module")
def models():
    return {name: cmbs.load(name) for name in (RED, GEN)}


@pytest.fixture(scope="module")
def runs(models):
    """Servo runs by (model, method, dt), computed once."""
    cache = {}

    def run(name: str, method: str, dt: float):
        key = (name, method, dt)
        if key not in cache:
            model = models[name]
            output = segment_point(model, "link3")
            start = output.value(model.q0)
            cache[key] = servo_inverse_dynamics(model, output, LinePath(start, start + SHIFT, DURATION), grid(dt),
                                                method=method)
        return cache[key]

    return run


def angles(result) -> np.ndarray:
    return np.column_stack([result.trajectory[f"theta{k}"] for k in (1, 2, 3)])


def link3_com(model, q: np.ndarray) -> np.ndarray:
    """Independent of servo.py: the midpoint of link 3's ends from the model's compiled point
    kinematics (the COM is at mid-link, com = (2.5, 0) on a 5 m link)."""
    points = model.point_positions(q)
    names = model.point_names
    if "P2" in names:  # natural coordinates: link 3 from P2 to P3
        return 0.5 * (points[names.index("P2")] + points[names.index("P3")])
    return 0.5 * (points[names.index("link3.origin")] + points[names.index("link3.end")])


# ------------------------------------------------------------------------------ outputs
@pytest.mark.parametrize("segment, ends", [("link1", ("O", "P1")), ("link3", ("P2", "P3"))])
def test_natural_segment_point_is_the_segment_com(models, segment, ends):
    """The COM at mid-segment (link 1 hangs from the fixed point O: a constant part)."""
    model = models[RED]
    output = segment_point(model, segment)
    rng = np.random.default_rng(1)
    for _ in range(3):
        q = model.q0 + rng.normal(size=model.n)
        points = model.point_positions(q)
        middle = 0.5 * (points[model.point_names.index(ends[0])] + points[model.point_names.index(ends[1])])
        np.testing.assert_allclose(output.value(q), middle, atol=1e-13)
        jacobian = np.array([(output.value(q + e * 1e-6) - output.value(q - e * 1e-6)) / 2e-6
                             for e in np.eye(model.n)]).T
        np.testing.assert_allclose(output.jacobian(q), jacobian, atol=1e-8)
        assert np.all(output.bias(q, rng.normal(size=model.n)) == 0.0)  # linear in q
    assert output.names == (f"{segment}.com.x", f"{segment}.com.z")


def test_natural_segment_point_off_axis_on_a_fixed_point():
    """A point off the axis of the four-bar's rocker P2-B (B fixed at (10, 0)): thesis eq. 3.32,
    r = r_i + (ξ/L)(r_j - r_i) + (η/L) R90 (r_j - r_i)."""
    model = cmbs.load("four-bar")
    output = segment_point(model, "rocker", (1.5, 0.4))
    q = model.q0 + np.random.default_rng(3).normal(size=model.n)
    points = model.point_positions(q)
    p2, b = points[model.point_names.index("P2")], points[model.point_names.index("B")]
    d = b - p2
    np.testing.assert_allclose(output.value(q), p2 + 0.25 * d + (0.4 / 6.0) * np.array([-d[1], d[0]]), atol=1e-13)
    assert output.names == ("rocker(1.5,0.4).x", "rocker(1.5,0.4).z")


def prismatic_arm():
    """A turning base, a prismatic joint on it (its Coriolis term needs the rotating parent) and a
    revolute link with a named point off its axis."""
    b = JointModelBuilder("slider-arm", gravity=(0.0, -9.81))
    b.add_link("base", parent=None, coordinate="psi", origin=(0.1, 0.2), length=0.5, mass=1.0, com=(0.25, 0.0),
               inertia=0.02, q0=0.4)
    b.add_link("slider", parent="base", joint="prismatic", coordinate="s", origin=(0.2, -0.1), angle=0.5,
               length=0.4, mass=2.0, com=(0.2, 0.0), inertia=0.05, q0=0.3)
    b.add_link("arm", parent="slider", coordinate="phi", origin=(0.4, 0.1), angle=0.2, length=1.0, mass=1.0,
               com=(0.5, 0.0), inertia=1 / 12, q0=0.7)
    b.add_point("tip", link="arm", local=(0.8, 0.15))
    b.add_actuator("f", coordinate="s")
    b.add_actuator("tau", coordinate="phi")
    return b.build()


@pytest.mark.parametrize("case", ["passive-manipulator-joint", "prismatic"])
def test_joint_segment_point_matches_the_compiled_kinematics(models, case):
    """Value against the kernel's point positions, C against central differences, Ċq̇ against
    d²Ψ(q(t))/dt² - C q̈ along smooth motions."""
    if case == "prismatic":
        model = prismatic_arm()
        output = segment_point(model, "arm", (0.8, 0.15))
        reference = lambda q: model.point_positions(q)[model.point_names.index("tip")]
    else:
        model = models[GEN]
        output = segment_point(model, "link3")
        reference = lambda q: link3_com(model, q)
    rng = np.random.default_rng(2)
    for _ in range(3):
        path = SmoothPath(model.q0, rng, amplitude=1.0)
        t = float(rng.uniform(0.0, 2.0))
        q, qd, qdd = path.q(t), path.qd(t), path.qdd(t)
        np.testing.assert_allclose(output.value(q), reference(q), atol=1e-13)
        jacobian = np.array([(reference(q + e * 1e-6) - reference(q - e * 1e-6)) / 2e-6 for e in np.eye(model.n)]).T
        np.testing.assert_allclose(output.jacobian(q), jacobian, atol=1e-8)
        second = second_derivative_fd(lambda s: reference(path.q(s)), t)
        np.testing.assert_allclose(output.bias(q, qd), second - output.jacobian(q) @ qdd, atol=1e-6)


def test_callable_output_gives_the_same_solution(models, runs):
    """Ψ as a plain callable (derivatives by differences) reproduces the exact output's run."""
    model = models[RED]

    def com(q):
        return 0.5 * (q[2:4] + q[4:6])

    start = com(model.q0)
    times = grid(0.01, 1.0)
    for method in ("full", "projected"):
        exact = runs(RED, method, 0.01)
        result = servo_inverse_dynamics(model, com, LinePath(start, start + SHIFT, DURATION), times, method=method)
        assert result.output_names == ("y[0]", "y[1]")
        np.testing.assert_allclose(result.trajectory.q, exact.trajectory.q[:times.size], atol=1e-9)
        np.testing.assert_allclose(result.u, exact.u[:times.size], atol=1e-6 * np.abs(exact.u).max())


def test_line_path_derivatives_and_rest_ends():
    path = LinePath([7.5, 5.0], [5.5, 3.0], DURATION)
    for t in (0.4, 1.5, 2.2):
        np.testing.assert_allclose(path(t)[1], first_derivative_fd(lambda s: path(s)[0], t), atol=1e-9)
        np.testing.assert_allclose(path(t)[2], second_derivative_fd(lambda s: path(s)[0], t), atol=1e-7)
    for t in (0.0, DURATION, DURATION + 1.0):
        assert not path(t)[1].any() and not path(t)[2].any()
    np.testing.assert_allclose(path(DURATION)[0], [5.5, 3.0], atol=1e-15)
    np.testing.assert_allclose(path(DURATION / 2)[0], [6.5, 4.0], atol=1e-15)  # s(½) = ½


# ------------------------------------------------------------------------------ the step equations hold
def test_start_accelerations_solve_the_continuous_equations():
    """A moving start (prismatic arm, tip at constant velocity, ÿ = 0): (a₀, λ₀, u₀) satisfy
    M a₀ = Q(u₀) and the tip's acceleration along q₀ + εq̇₀ + ε²a₀/2 (compiled point kinematics,
    second difference) is ÿ(0) = 0."""
    model = prismatic_arm()
    output = segment_point(model, "arm", (0.8, 0.15))
    q0, qd0 = model.q0.copy(), np.array([0.7, -0.4, 1.1])
    y0, yd0 = output.value(q0), output.jacobian(q0) @ qd0
    reference = lambda t: (y0 + yd0 * t, yd0, np.zeros(2))
    result = servo_inverse_dynamics(model, output, reference, [0.0, 0.01], qd0=qd0)
    a0, u0 = result.trajectory.qdd[0], result.u[0]
    terms = model.evaluate(q0, qd0, 0.0, u0)
    np.testing.assert_allclose(terms.M @ a0, terms.Q, atol=1e-10 * np.abs(terms.Q).max())
    tip = lambda q: model.point_positions(q)[model.point_names.index("tip")]
    acceleration = second_derivative_fd(lambda e: tip(q0 + e * qd0 + 0.5 * e * e * a0), 0.0, h=5e-4)
    assert np.abs(acceleration).max() < 1e-7  # difference error ~2e-9 (|a₀| ~ 100)
    assert np.abs(output.bias(q0, qd0)).max() > 0.1  # the velocity terms matter here



@pytest.mark.parametrize("name", [RED, GEN])
@pytest.mark.parametrize("method", ["full", "projected"])
def test_every_step_satisfies_its_equations(models, runs, name, method):
    """Recomputed from the model: Φ = 0 and c = 0 to the Newton tolerance at every step, the
    backward-Euler relations, and the dynamics rows of the method."""
    model, result, tol = models[name], runs(name, method, 0.01), 1e-10
    traj = result.trajectory
    path = LinePath(link3_com(model, model.q0), link3_com(model, model.q0) + SHIFT, DURATION)
    output = segment_point(model, "link3")
    h = np.diff(traj.t)[:, None]
    np.testing.assert_allclose(traj.qd[1:], traj.qd[:-1] + h * traj.qdd[1:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(traj.q[1:], traj.q[:-1] + h * traj.qd[1:], rtol=0, atol=1e-12)
    assert result.iterations[1:].min() >= 1 and result.iterations.max() <= 4
    for i, t in enumerate(traj.t):
        q, v, a, lam, u = traj.q[i], traj.qd[i], traj.qdd[i], result.lam[i], result.u[i]
        assert np.abs(model.constraints(q, t)).max(initial=0.0) <= tol
        assert np.abs(link3_com(model, q) - path(t)[0]).max() <= tol
        terms = model.evaluate(q, v, t, u)
        residual = terms.M @ a + terms.A.T @ lam - terms.Q
        scale = 1.0 + max(np.abs(terms.M @ a).max(), np.abs(terms.Q).max(), np.abs(terms.A.T @ lam).max(initial=0))
        if method == "full" or i == 0:
            assert np.abs(residual).max() <= tol * scale
        else:  # Dᵀ r = 0 <=> r in range(Cᵀ)
            C = output.jacobian(q)
            off = residual - C.T @ np.linalg.lstsq(C.T, residual, rcond=None)[0]
            assert np.abs(off).max() <= 10 * tol * scale
            assert np.abs(residual).max() > 1e3 * tol * scale  # r itself is not 0: this is not the full scheme
    assert result.constraint_residual.max() <= tol and result.servo_residual.max() <= tol


def test_projected_method_meets_the_servo_constraint_at_acceleration_level(models, runs):
    """GEN (M regular, no Φ): the continuous acceleration q̈ = M⁻¹Q(q, v, u) of every step makes
    the COM (compiled point kinematics, second difference in ε along q + εv + ε²q̈/2) accelerate
    exactly as prescribed: c̈ = 0 at t_{n+1}."""
    model, result = models[GEN], runs(GEN, "projected", 0.01)
    start = link3_com(model, model.q0)
    path = LinePath(start, start + SHIFT, DURATION)
    worst = 0.0
    for i in range(1, result.t.size, 7):
        q, v, u = result.trajectory.q[i], result.trajectory.qd[i], result.u[i]
        terms = model.evaluate(q, v, result.t[i], u)
        qdd = np.linalg.solve(terms.M, terms.Q)
        acceleration = second_derivative_fd(lambda e: link3_com(model, q + e * v + 0.5 * e * e * qdd), 0.0, h=2e-3)
        worst = max(worst, np.abs(acceleration - path(result.t[i])[2]).max())
    assert worst < 1e-7  # the difference formula's error (~1e-9); the full method misses by O(h):
    full = runs(GEN, "full", 0.01)
    q, v, u = full.trajectory.q[150], full.trajectory.qd[150], full.u[150]
    terms = model.evaluate(q, v, full.t[150], u)
    qdd = np.linalg.solve(terms.M, terms.Q)
    miss = second_derivative_fd(lambda e: link3_com(model, q + e * v + 0.5 * e * e * qdd), 0.0, h=2e-3)
    assert np.abs(miss - path(full.t[150])[2]).max() > 1e-2  # measured 0.069 m/s² at t = 1.5 s


# ------------------------------------------------------------------------------ first-order agreement
def differences(first, second) -> tuple[float, float]:
    return float(np.abs(angles(first) - angles(second)).max()), float(np.abs(first.u - second.u).max())


@pytest.mark.parametrize("method", ["full", "projected"])
def test_red_and_gen_agree_to_first_order(runs, method):
    """Backward Euler on different coordinates: the same solution up to O(h).  Bounds at
    h = 0.01 (measured 0.187 rad / 274 N m full, 0.023 rad / 35 N m projected; |τ| reaches 880 N m)
    and the halving with h (measured ratios 2.0-2.1)."""
    coarse = differences(runs(RED, method, 0.01), runs(GEN, method, 0.01))
    fine = differences(runs(RED, method, 0.005), runs(GEN, method, 0.005))
    bound = {"full": (0.25, 350.0), "projected": (0.035, 50.0)}[method]
    assert coarse[0] < bound[0] and coarse[1] < bound[1]
    for before, after in zip(coarse, fine):
        assert 1.7 < before / after < 2.4


@pytest.mark.parametrize("name", [RED, GEN])
def test_full_and_projected_agree_to_first_order(runs, name):
    """The two discretisations differ in the servo direction (BE acceleration vs the exact
    acceleration-level condition), so they agree to O(h), not to round-off (servo.py docstring):
    measured at h = 0.01: RED 0.021 rad / 23 N m, GEN 0.143 rad / 245 N m; ratios ~2."""
    coarse = differences(runs(name, "full", 0.01), runs(name, "projected", 0.01))
    fine = differences(runs(name, "full", 0.005), runs(name, "projected", 0.005))
    bound = {RED: (0.03, 35.0), GEN: (0.2, 330.0)}[name]
    assert coarse[0] < bound[0] and coarse[1] < bound[1]
    for before, after in zip(coarse, fine):
        assert 1.7 < before / after < 2.4


# ------------------------------------------------------------------------------ replay
@pytest.mark.parametrize("name", [RED, GEN])
def test_replayed_inputs_reproduce_the_path(models, runs, name):
    """τ(t) (cubic spline through the samples) in a forward simulation (rk45, rtol 1e-10) from the
    same start: the link-3 COM follows the path within the O(h) error of the backward-Euler
    inputs — bound 0.06 m at h = 0.01 (measured 0.048 RED, 0.035 GEN over a 2.8 m path), halving
    with h."""
    model = models[name]
    start = link3_com(model, model.q0)
    path = LinePath(start, start + SHIFT, DURATION)
    errors = []
    for dt in (0.01, 0.005):
        result = runs(name, "full", dt)
        run = cmbs.simulate(model, t_end=DURATION, u=cmbs.SampledInput(result.t, result.u, "spline"), rtol=1e-10,
                            atol=1e-12, dt=0.01)
        assert run.info["status"] == "success"
        errors.append(max(np.abs(link3_com(model, q) - path(t)[0]).max() for q, t in zip(run.q, run.t)))
    assert errors[0] < 0.06
    assert 1.7 < errors[0] / errors[1] < 2.4


# ------------------------------------------------------------------------------ fully actuated sanity cases
def joint_pendulum():
    b = JointModelBuilder("pendulum-joint", gravity=(0.0, -9.81))
    b.add_link("rod", parent=None, coordinate="theta", length=1.0, mass=2.0, com=(0.5, 0.0), inertia=2.0 / 12,
               q0=0.3)
    b.add_actuator("tau", coordinate="theta")
    return b.build()


def test_pendulum_torque_matches_the_closed_form():
    """θ(t) = 0.3 + 0.5 sin 2t prescribed on a pendulum: τ = I_O θ̈ + m g (L/2) cos θ.  The
    projected method imposes the exact acceleration with the exact θ(t_{n+1}) and Q has no
    velocity terms, so it is exact at every step; the full method's second difference makes it
    O(h)."""
    model = joint_pendulum()

    def reference(t):
        return np.array([0.3 + 0.5 * math.sin(2 * t)]), np.array([math.cos(2 * t)]), np.array([-2.0 * math.sin(2 * t)])

    errors = []
    for dt in (0.01, 0.005):
        times = grid(dt, 2.0)
        theta = 0.3 + 0.5 * np.sin(2 * times)
        exact = (2.0 / 12 + 2.0 * 0.25) * (-2.0 * np.sin(2 * times)) + 2.0 * 9.81 * 0.5 * np.cos(theta)
        output = coordinate_output(model, ["theta"])
        projected = servo_inverse_dynamics(model, output, reference, times, method="projected", qd0=np.array([1.0]))
        assert np.abs(projected.input("tau") - exact).max() < 1e-8
        full = servo_inverse_dynamics(model, output, reference, times, qd0=np.array([1.0]))
        errors.append(np.abs(full.input("tau") - exact).max())
    assert errors[0] < 0.03 and 1.9 < errors[0] / errors[1] < 2.1


def driven_double_pendulum():
    """The library two-link arm (the double pendulum with torques on θ1, θ2) with θ1, θ2 prescribed."""
    arm = cmbs.load("two-link-arm", theta1=-0.6, theta2=0.3)
    return prescribe(arm, read_motion("theta1 = -0.6 + 0.4*sin(2*t); theta2 = 0.3 + 0.5*sin(3*t)", arm))


def test_fully_actuated_double_pendulum_matches_inverse_dynamics():
    """Outputs = the model's own angles (m̃ = DOF = 2): the servo inputs converge at first order
    to the driver torques of cmbs.inverse_dynamics on the driven model.  The first step is left
    out: with v₀ exact, a₁ = ((q₁ - q₀)/h - v₀)/h ≈ q̈₀/2, backward Euler's O(1) start layer when
    the start acceleration is not 0 (the points' centripetal acceleration here)."""
    driven = driven_double_pendulum()
    free = driven.without_drivers()

    def reference(t):
        return (np.array([-0.6 + 0.4 * math.sin(2 * t), 0.3 + 0.5 * math.sin(3 * t)]),
                np.array([0.8 * math.cos(2 * t), 1.5 * math.cos(3 * t)]),
                np.array([-1.6 * math.sin(2 * t), -4.5 * math.sin(3 * t)]))

    errors = []
    for dt in (0.01, 0.005):
        times = grid(dt, 2.0)
        ida = cmbs.inverse_dynamics(driven, times)
        torque = np.column_stack([ida.force("theta1"), ida.force("theta2")])
        result = servo_inverse_dynamics(free, coordinate_output(free, ["theta1", "theta2"]), reference, times,
                                        q0=ida.motion.q[0], qd0=ida.motion.qd[0])
        np.testing.assert_allclose(result.trajectory.q, ida.motion.q, atol=1e-9)  # the outputs fix q
        errors.append(np.abs(result.u[2:] - torque[2:]).max())
        assert errors[-1] < 0.02 * np.abs(torque).max()  # measured 0.30 N m of 19.3 at h = 0.01
    assert 1.8 < errors[0] / errors[1] < 2.2
    with pytest.raises(CmbsError, match="coordinates with mass"):  # angle coordinates carry no mass
        servo_inverse_dynamics(free, coordinate_output(free, ["theta1", "theta2"]), reference, grid(0.01, 0.1),
                               q0=ida.motion.q[0], qd0=ida.motion.qd[0], method="projected")


# ------------------------------------------------------------------------------ failures
@pytest.mark.parametrize("method", ["full", "projected"])
def test_path_leaving_the_workspace_stops_with_time_residual_and_reason(models, method):
    """COM towards (20, 5): beyond the 12.5 m the arm can reach, and link 3 trails so the elbow
    joint leaves its 10 m disc before that.  The error names the time, the residual and why."""
    model = models[RED]
    times = grid(0.01)
    with pytest.raises(ServoConvergenceError) as caught:
        servo_inverse_dynamics(model, segment_point(model, "link3"), LinePath([7.5, 5.0], [20.0, 5.0], DURATION),
                               times, method=method)
    error = caught.value
    assert 0.5 < error.t < 2.0 and error.value > 1e-6
    message = str(error)
    assert f"no solution at t = {error.t:.6g} s" in message and "h = 0.01" in message
    assert error.residual in message and "not realisable" in message
    reach = np.hypot(*LinePath([7.5, 5.0], [20.0, 5.0], DURATION)(error.t)[0])
    assert reach < 12.5  # it stops before the COM itself is out of reach: the trailing link is


def test_singular_start_is_reported():
    """Links 1-3 stretched along x: the COM cannot be accelerated radially by τ1, τ2."""
    model = cmbs.load(GEN)
    q0 = np.zeros(3)
    with pytest.raises(ServoConvergenceError, match="singular.*cannot steer"):
        servo_inverse_dynamics(model, segment_point(model, "link3"), LinePath([12.5, 0.0], [11.0, 1.0], 1.0),
                               grid(0.01, 1.0), q0=q0, qd0=np.zeros(3))


def test_user_mistakes_are_named(models):
    model = models[GEN]
    output = segment_point(model, "link3")
    path = LinePath([7.5, 5.0], [5.5, 3.0], DURATION)
    times = grid(0.01, 0.1)
    with pytest.raises(CmbsError, match="no link 'link4'; links: link1, link2, link3"):
        segment_point(model, "link4")
    with pytest.raises(CmbsError, match="unknown servo method 'exact'"):
        servo_inverse_dynamics(model, output, path, times, method="exact")
    with pytest.raises(CmbsError, match="as many distinct inputs as outputs: 2 outputs"):
        servo_inverse_dynamics(model, output, path, times, inputs=["tau1"])
    with pytest.raises(CmbsError, match="no actuator"):
        servo_inverse_dynamics(model, output, path, times, inputs=["tau1", "tau3"])
    with pytest.raises(CmbsError, match=r"start state .* inconsistent: Ψ\(q0\) - y_ref\(t0\)"):
        servo_inverse_dynamics(model, output, LinePath([7.0, 5.0], [5.5, 3.0], DURATION), times)
    with pytest.raises(CmbsError, match="times must be"):
        servo_inverse_dynamics(model, output, path, [0.0, 0.1, 0.1])
    with pytest.raises(CmbsError, match=r"y_ref\(t\) must return"):
        servo_inverse_dynamics(model, output, lambda t: np.zeros(2), times)
    with pytest.raises(CmbsError, match="line path: duration"):
        LinePath([0.0, 0.0], [1.0, 1.0], 0.0)


def test_callable_output_derivatives_match_the_exact_point_output():
    """A user's Ψ(q) (the link-3 centre of mass from the drawn points) with its derivatives by
    differences against the exact segment_point of the joint-angle model."""
    model = cmbs.load("passive-manipulator-joint")
    exact = segment_point(model, "link3")

    def centre(q):
        points = model.point_positions(q)
        return 0.5 * (points[4] + points[5])          # link3.origin and link3.end

    user = callable_output(centre, ("x", "z"))
    rng = np.random.default_rng(5)
    for _ in range(3):
        q, qd = rng.uniform(-2.0, 2.0, 3), rng.normal(size=3)
        np.testing.assert_allclose(user.value(q), exact.value(q), atol=1e-12)
        np.testing.assert_allclose(user.jacobian(q), exact.jacobian(q), atol=1e-9)
        np.testing.assert_allclose(user.bias(q, qd), exact.bias(q, qd), atol=1e-6)
