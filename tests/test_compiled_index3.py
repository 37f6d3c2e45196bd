"""Backward Euler and generalized-α compiled (cmbs.integrate.compiled_index3 on the Newton loop of
cmbs.integrate.implicit): against the closed-form small oscillation of the pendulum, to the
schemes' orders; against the same loop run interpreted on a Python residual (the path of runs
with Python callables: the same residual routine, the tangent routine run as Python, numpy's solve);
and the failures, which end the run with the messages of the Python path."""

import json
import math
import os
import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pytest

import cmbs
from cmbs import jit
from cmbs.control import ComputedTorque, Reference, ZeroOrderHold
from cmbs.model.natural import NaturalModelBuilder
from cmbs.simulate import simulate

#: the rod pendulum of the library (1 m, 1 kg, I_O = m l²/3): θ̈ = -(3g / 2l) sin θ
OMEGA = math.sqrt(1.5 * 9.81)
THETA0 = 1e-3


def small_swing(integrator: str, dt: float, t_end: float = 1.0, **options) -> cmbs.Trajectory:
    """The pendulum released at rest THETA0 from hanging (P at (sin θ0, -cos θ0))."""
    model = cmbs.load("pendulum")
    start = np.array([math.sin(THETA0), -math.cos(THETA0)])
    return simulate(model, t_end=t_end, integrator=integrator, dt=dt, q0=start, qd0=np.zeros(2), **options)


def angle_error(run: cmbs.Trajectory) -> float:
    """Largest |θ - θ0 cos ωt| over the run (the linearised motion: its own error is of order
    θ0³ ω t / 16 ≈ 3e-10 rad here, far below the schemes' errors)."""
    theta = np.arctan2(run["P.x"], -run["P.z"])
    return float(np.abs(theta - THETA0 * np.cos(OMEGA * run.t)).max())


@pytest.mark.parametrize("integrator, order, steps, largest", [
    ("backward-euler", 1, (2e-3, 1e-3), 3e-5),
    ("generalized-alpha", 2, (1e-2, 5e-3), 3e-6),
])
def test_compiled_schemes_follow_the_small_oscillation_to_their_order(integrator, order, steps, largest):
    runs = [small_swing(integrator, dt) for dt in steps]
    assert all(run.info["status"] == "success" and run.info["compiled"] for run in runs)
    errors = [angle_error(run) for run in runs]
    assert errors[0] < largest
    assert math.log2(errors[0] / errors[1]) == pytest.approx(order, abs=0.15)


def test_one_residual_routine_compiled_and_run_as_python():
    """r_dyn = M a + Aᵀλ - Q (cmbs.integrate.implicit.dynamic_residual), which the compiled problems
    and the runs on Python calls share: compiled and run as Python (without numba) it gives the
    same bits, and numpy's formula to rounding."""
    from cmbs.integrate.implicit import dynamic_residual

    rng = np.random.default_rng(4)
    n, m = 5, 3
    M, A, Q, a, lam = (rng.normal(size=shape) for shape in ((n, n), (m, n), n, n, m))
    compiled, python = np.empty(n), np.empty(n)
    dynamic_residual(M, A, Q, a, lam, compiled)
    jit.interpreted(dynamic_residual)(M, A, Q, a, lam, python)
    np.testing.assert_array_equal(compiled, python)
    expected = M @ a + A.T @ lam - Q
    np.testing.assert_allclose(compiled, expected, rtol=0, atol=1e-14 * (np.abs(M).max() * np.abs(a).sum()
                                                                         + np.abs(A).max() * np.abs(lam).sum()
                                                                         + np.abs(Q).max()))


@pytest.mark.parametrize("integrator, name", [("backward-euler", "four-bar"), ("generalized-alpha", "four-bar"),
                                              ("generalized-alpha", "slider-crank-joint")])
def test_compiled_loop_equals_the_loop_on_a_python_residual(integrator, name):
    """The driven four-bar (natural coordinates, constant M) and the slider-crank in joint
    coordinates (M(q)), 2 s: the compiled run and the run on Python calls (compiled=False:
    numpy's model evaluation, solve and tangents) take the same Newton iterations to the same
    motion.  Newton stops on the positions (h² b' max|Δa| below 1e-10 (1 + max|q|)), so a, and λ
    with it, are settled only to that accuracy: q̈ agrees to 1e-6, and the constraint forces -Aᵀλ
    (λ Newton's in the one, least squares at the output in the other) to 1e-7 of their size; λ
    itself to that divided by σ_min(A), which nears zero as the slider-crank nears its singular
    position (2 s)."""
    model = cmbs.load(name)
    fast, slow = (simulate(model, t_end=2.0, integrator=integrator, dt=2e-3, compiled=flag) for flag in (None, False))
    assert fast.info["compiled"] and "compiled" not in slow.info
    assert fast.info["status"] == slow.info["status"] == "success"
    for key in ("steps", "newton_iterations", "evaluations"):
        assert fast.info[key] == slow.info[key], key
    np.testing.assert_array_equal(fast.t, slow.t)
    np.testing.assert_allclose(fast.q, slow.q, rtol=0, atol=1e-11)
    np.testing.assert_allclose(fast.qd, slow.qd, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.qdd, slow.qdd, rtol=0, atol=1e-6)
    force = np.abs(slow["constraint_force"]).max()
    np.testing.assert_allclose(fast["constraint_force"], slow["constraint_force"], rtol=0, atol=1e-7 * force)
    smallest = np.array([np.linalg.svd(model.jacobian(q, t), compute_uv=False).min() for q, t in zip(slow.q, slow.t)])
    assert np.all(np.abs(fast["lam"] - slow["lam"]).max(axis=1) <= 1e-7 * force / smallest)
    np.testing.assert_allclose(fast["energy"], slow["energy"], rtol=0, atol=1e-9)


@pytest.fixture(scope="module")
def four_bar_control():
    """The undriven four-bar, its driven motion α(t) as reference, and a start 0.1 rad off it."""
    driven = cmbs.load("four-bar")
    motion = cmbs.kinematic_analysis(driven, np.linspace(0.0, 1.0, 1001))
    plant = driven.without_drivers()
    start = motion.q[0].copy()
    start[plant.coordinate_index("alpha")] += 0.1
    return plant, Reference(motion, ("alpha",)), cmbs.assemble(plant, start, fixed=["alpha"])


@pytest.mark.parametrize("held", [False, True])
def test_computed_torque_in_the_compiled_loop_equals_the_python_law(four_bar_control, held):
    """The compiled law (at every residual and shifted state, or sampled at each step's first
    iterate and held) gives the Python law's run, and the tracking error follows the designed
    ë + 20ė + 100e = 0 to the scheme's error.  A held sample is taken at the step's predicted
    state, which depends on the accelerations Newton settles only to its tolerance (see above):
    u agrees to 1e-6 of its size."""
    plant, reference, start = four_bar_control

    def law():
        computed = ComputedTorque(plant, reference, kp=100.0, kd=20.0)
        return ZeroOrderHold(computed, period=1e-3) if held else computed

    fast, slow = (simulate(plant, t_end=0.5, integrator="generalized-alpha", dt=1e-3, u=law(), q0=start,
                           qd0=np.zeros(plant.n), compiled=flag) for flag in (None, False))
    assert fast.info["compiled"] and "compiled" not in slow.info
    assert fast.info["status"] == slow.info["status"] == "success"
    np.testing.assert_allclose(fast.q, slow.q, rtol=0, atol=1e-10)
    np.testing.assert_allclose(fast["u"], slow["u"], rtol=0, atol=1e-6 * np.abs(slow["u"]).max())
    error = reference.motion["alpha"][:fast.t.size] - fast["alpha"]
    designed = -0.1 * (1 + 10 * fast.t) * np.exp(-10 * fast.t)
    assert np.abs(error - designed).max() < 1e-3


def redundant_four_bar() -> cmbs.Model:
    """The library four-bar (undriven) with its coupler constraint given twice: A has rank 4 < 5,
    and the Newton matrix [.. Aᵀ; A 0] is singular."""
    b = NaturalModelBuilder("four-bar-redundant")
    b.add_point("A", 0.0, 0.0, fixed=True)
    b.add_point("B", 10.0, 0.0, fixed=True)
    base = cmbs.load("four-bar")
    b.add_point("P1", *base.q0[0:2])
    b.add_point("P2", *base.q0[2:4])
    b.add_segment("crank", "A", "P1", mass=1.0, com=(1.0, 0.0), inertia=1 / 3, length=2.0)
    b.add_segment("coupler", "P1", "P2", mass=5.0, com=(5.0, 0.0), inertia=5 * 100 / 12, length=10.0)
    b.add_segment("coupler-again", "P1", "P2", mass=0.0, length=10.0)
    b.add_segment("rocker", "P2", "B", mass=3.0, com=(3.0, 0.0), inertia=9.0, length=6.0)
    b.add_angle("alpha", segment="crank")
    return b.build()


SINGULAR_FORCE = """
[points]
O = { x = 0.0, z = 0.0, fixed = true }
P = { x = 1.0, z = 0.0 }

[segments.crank]
points = ["O", "P"]
mass = 1.0
com = [0.5, 0.0]
inertia = 0.1

[forces.f]
point = "P"
fz = "1/(t-0.5)"
"""


def failures(tmp_path):
    """(model, options, the message's start, the last output kept) of each way the Newton loop fails."""
    path = tmp_path / "singular.toml"
    path.write_text(SINGULAR_FORCE)
    return [
        (redundant_four_bar(), {}, "singular Newton matrix at t=0.01 (redundant constraints or a singular "
                                   "configuration)", 0.0),
        (cmbs.load("four-bar"), {"newton_tolerance": 1e-30},
         "Newton iteration did not converge in 25 iterations at t=0.01 (last correction ", 0.0),
        (cmbs.load(path), {}, "Newton iteration diverged at t=0.5 (force f (fz) ('1/(t-0.5)') is not finite at "
                              "t = 0.5: inf, -inf, nan)", 0.49),
    ]


@pytest.mark.parametrize("integrator", ["backward-euler", "generalized-alpha"])
def test_failures_end_the_run_with_the_python_paths_message(tmp_path, integrator):
    for model, options, message, last in failures(tmp_path):
        runs = [simulate(model, t_end=1.0, integrator=integrator, dt=0.01, compiled=flag, **options)
                for flag in (None, False)]
        assert runs[0].info["compiled"] and "compiled" not in runs[1].info
        for run in runs:
            assert run.info["status"] == "failed", model.name
            assert run.info["message"].startswith(message), run.info["message"]
            assert run.t[-1] == pytest.approx(last, abs=1e-12) and np.all(np.isfinite(run.q))
        np.testing.assert_allclose(runs[0].q, runs[1].q, rtol=0, atol=1e-11)


def pendulum_forced_to_infinity() -> cmbs.Model:
    """A unit point mass on a unit rod about the origin, from Python functions, whose force becomes
    infinite at t = 0.5."""
    from cmbs.model.equations import from_callables

    return from_callables("forced-to-infinity", coordinate_names=["x", "z"], mass_matrix=lambda q: np.eye(2),
                          forces=lambda q, qd, t, u: np.array([0.0, -9.81 if t < 0.5 else np.inf]),
                          constraints=lambda q, t: np.array([q[0] ** 2 + q[1] ** 2 - 1.0]),
                          jacobian=lambda q, t: np.array([[2.0 * q[0], 2.0 * q[1]]]),
                          gamma=lambda q, qd, t: np.array([-2.0 * (qd[0] ** 2 + qd[1] ** 2)]),
                          q0=[math.sin(0.3), -math.cos(0.3)])


@pytest.mark.parametrize("integrator", ["backward-euler", "generalized-alpha"])
def test_a_diverging_run_on_python_calls_fails_with_the_message_and_no_numpy_warning(tmp_path, integrator):
    """Forces that become infinite at t = 0.5 (a model file's time function 1/(t - 0.5) run on
    Python calls, and a model of Python functions): the run ends failed at the last output
    before 0.5 with Newton's divergence message, as the compiled run does, and numpy warns of
    nothing (the tangents' forward differences took inf - inf: 'invalid value encountered in
    subtract')."""
    path = tmp_path / "singular.toml"
    path.write_text(SINGULAR_FORCE)
    for model in (cmbs.load(path), pendulum_forced_to_infinity()):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            run = simulate(model, t_end=1.0, integrator=integrator, dt=0.01, compiled=False)
        assert [str(warning.message) for warning in caught] == [], model.name
        assert run.info["status"] == "failed", model.name
        assert run.info["message"].startswith("Newton iteration diverged at t=0.5"), run.info["message"]
        assert run.t[-1] == pytest.approx(0.49, abs=1e-12) and np.all(np.isfinite(run.q))


ALLOCATIONS = textwrap.dedent("""
    import gc
    import json

    from numba.core.runtime import rtsys

    import cmbs

    model = cmbs.load("four-bar")
    counts = []
    for t_end in (0.05, 0.05, 0.1):          # the first run compiles and warms the caches
        gc.collect()
        before = rtsys.get_allocation_stats()
        run = cmbs.simulate(model, t_end=t_end, integrator="generalized-alpha", dt=1e-3)
        assert run.info["compiled"] and run.info["status"] == "success"
        del run
        gc.collect()
        after = rtsys.get_allocation_stats()
        counts.append([after.alloc - before.alloc, after.free - before.free])
    print(json.dumps(counts[1:]))
""")


@pytest.mark.skipif(not jit.COMPILED, reason="numba's statistics: numba is not installed")
def test_compiled_loop_frees_what_it_allocates_and_allocates_nothing_per_step():
    """numba's allocation statistics (on at interpreter start, hence the subprocess): a run of 100
    steps allocates as much as one of 50 (the work arrays are allocated once per run), and frees
    all of it."""
    environment = {**os.environ, "NUMBA_NRT_STATS": "1", "OPENBLAS_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-c", ALLOCATIONS], capture_output=True, text=True, env=environment,
                          timeout=1500)
    assert done.returncode == 0, done.stderr[-3000:]
    short, long = json.loads(done.stdout.strip().splitlines()[-1])
    assert short[0] == short[1] and long[0] == long[1]
    assert long == short


def test_trapezoidal_rule_on_a_fully_driven_mechanism_is_its_kinematics():
    """The driven four-bar has no independent coordinate: the trapezoidal rule's Newton loop has
    no unknowns (it stopped with a ValueError on an empty max) and the motion is the kinematic
    analysis's, positions, velocities and accelerations."""
    model = cmbs.load("four-bar")
    run = simulate(model, t_end=1.0, integrator="trapezoidal", dt=0.01)
    assert run.info["status"] == "success" and run.t[-1] == pytest.approx(1.0)
    kinematics = cmbs.kinematic_analysis(model, run.t)
    np.testing.assert_allclose(run.q, kinematics.q, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.qd, kinematics.qd, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.qdd, kinematics.qdd, rtol=0, atol=1e-8)


def test_compiled_trapezoidal_rule_equals_the_loop_on_python_calls():
    """The undriven four-bar, 2 s at 10 ms in matrix R's independent coordinates: the compiled run
    (cmbs.integrate.compiled_reduced) and the run on Python calls (compiled=False: numpy's
    recovery, acceleration analysis, R and tangents) take the same Newton iterations to the same
    motion."""
    model = cmbs.load("four-bar").without_drivers()
    fast, slow = (simulate(model, t_end=2.0, integrator="trapezoidal", dt=0.01, compiled=flag) for flag in (None, False))
    assert fast.info["compiled"] and "compiled" not in slow.info
    assert fast.info["status"] == slow.info["status"] == "success"
    for key in ("steps", "newton_iterations", "evaluations"):
        assert fast.info[key] == slow.info[key], key
    np.testing.assert_allclose(fast.q, slow.q, rtol=0, atol=1e-11)
    np.testing.assert_allclose(fast.qd, slow.qd, rtol=0, atol=1e-10)
    np.testing.assert_allclose(fast.qdd, slow.qdd, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast["lam"], slow["lam"], rtol=0, atol=1e-9 * np.abs(slow["lam"]).max())


def test_compiled_trapezoidal_rule_repartitions_through_the_singular_position():
    """The slider-crank with gravity crosses θ1 = 90° at 0.83 s, where its partition must change;
    against its branch ODE (cmbs.library.mechanisms.slider_crank_branch) the compiled run errs
    as the Python one (2.8e-6 rad at 1 ms; tests/test_dynamics.py has the order) and re-partitions
    as it does."""
    from cmbs.library.mechanisms import slider_crank_branch

    model = cmbs.load("slider-crank", gravity=9.81)
    reference = slider_crank_branch(np.array([1.0]), gravity=9.81)[0][0]
    fast, slow = (simulate(model, t_end=1.0, integrator="trapezoidal", dt=1e-3, compiled=flag) for flag in (None, False))
    assert fast.info["compiled"] and fast.info["status"] == slow.info["status"] == "success"
    errors = [abs(run["theta1"][-1] - reference) for run in (fast, slow)]
    assert errors[0] < 3e-6 and errors[0] == pytest.approx(errors[1], rel=1e-3)
    assert fast.info["max_condition"] == pytest.approx(slow.info["max_condition"], rel=1e-6)
    assert fast.info["max_condition"] > 1e4            # the recovery met the singular position


def test_compiled_trapezoidal_rule_fails_with_the_python_paths_message(tmp_path):
    """A recovery that cannot converge (one Newton iteration for 1e-12) and forces that become
    infinite (1/(t - 0.5)) end the compiled run where the Python run ends, with its message."""
    path = tmp_path / "singular.toml"
    path.write_text(SINGULAR_FORCE)
    cases = [(cmbs.load("slider-crank", gravity=9.81), {"max_iterations": 1}, 0.0,
              "model 'slider-crank' at t=0.001: matrix-r position recovery did not converge in 1 iterations "
              "(residual 0.00399)"),
             (cmbs.load(path), {}, 0.49, "model 'singular' at t=0.5: non-finite forces or mass matrix (force f (fz) "
                                         "('1/(t-0.5)') is not finite at t = 0.5: inf, -inf, nan)")]
    for model, options, last, message in cases:
        runs = [simulate(model, t_end=1.0, integrator="trapezoidal", dt=1e-3 if last == 0.0 else 0.01,
                         compiled=flag, formulation_options=options) for flag in (None, False)]
        assert runs[0].info["compiled"] and "compiled" not in runs[1].info
        for run in runs:
            assert run.info["status"] == "failed" and run.info["message"] == message, run.info["message"]
            assert run.t[-1] == pytest.approx(last, abs=1e-12)
        np.testing.assert_allclose(runs[0].q, runs[1].q, rtol=0, atol=1e-9)
