"""The branch watch (cmbs.integrate.continuity): a run whose velocity jumps near a singular
configuration has left its assembly branch and ends as failed, keeping only the outputs before
the jump; a smooth motion, however fast, meets no alarm.

References: closed-form motions (a circular motion, a spin-up from rest, a velocity step smoothed
by tanh, with their exact accelerations), numpy's SVD, and for IFToMM A02 (the N-four-bar) the
geometry of its physical branch (every crank at the same angle: B_i - A_i the same for all i)
and the exact motion of B0 from the 1-DOF reduction (cmbs.library.n_four_bar.exact_b0).
"""

import math
import re

import numpy as np
import pytest

import cmbs
from cmbs.integrate.continuity import (JUMP_FROM, JUMP_SIZE, JUMP_TO, kept_records, left_branch, singularity,
                                       velocity_jump, watch_array)
from cmbs.library.n_four_bar import exact_b0


def watch_over(times, velocity, acceleration):
    """Feed the states (t, q̇(t), q̈(t)) to a new watch until it finds a jump, as a loop does: the
    time of the alarm ([] for none) and the watch."""
    watch = watch_array(len(velocity(times[0])), 0)
    for t in times:
        if velocity_jump(watch, float(t), velocity(t), acceleration(t)):
            return [t], watch
    return [], watch


def circle(omega):
    """q = (cos ωt, sin ωt): |q̇| = ω, |q̈| = ω²."""
    return (lambda t: omega * np.array([-math.sin(omega * t), math.cos(omega * t)]),
            lambda t: -omega ** 2 * np.array([math.cos(omega * t), math.sin(omega * t)]))


def test_a_fast_circular_motion_meets_no_alarm():
    velocity, acceleration = circle(200.0)            # 32 turns a second, |q̈| = 4e4
    for h in (1e-4, 1e-3, 4e-3):                       # h ω up to 0.8: RK4 is still stable there
        alarms, _ = watch_over(np.arange(0.0, 1.0, h), velocity, acceleration)
        assert alarms == []


def test_a_spin_up_from_rest_meets_no_alarm():
    """φ = α t²/2 from rest: |q̈| grows from α to α √(1 + α² t⁴) (5e6 at the end), a growth the
    lagged reference follows (the motion's own time scale shrinks as it speeds up)."""
    alpha = 1000.0

    def velocity(t):
        return alpha * t * np.array([-math.sin(alpha * t * t / 2), math.cos(alpha * t * t / 2)])

    def acceleration(t):
        phi, rate = alpha * t * t / 2, alpha * t
        return alpha * np.array([-math.sin(phi), math.cos(phi)]) - rate ** 2 * np.array([math.cos(phi), math.sin(phi)])

    alarms, _ = watch_over(np.linspace(0.0, 0.07, 7001), velocity, acceleration)
    assert alarms == []


def smoothed_step(v0, v1, t0, width, background):
    """q̇ = v0 + (v1 - v0)(1 + tanh((t - t0)/w))/2 + b (t - t0): a velocity jump over a time of order
    w on a motion of constant acceleration b, and its exact derivative."""
    v0, v1, background = np.asarray(v0, float), np.asarray(v1, float), np.asarray(background, float)
    return (lambda t: v0 + (v1 - v0) * (1 + math.tanh((t - t0) / width)) / 2 + background * (t - t0),
            lambda t: (v1 - v0) * (1 - math.tanh((t - t0) / width) ** 2) / (2 * width) + background)


def test_a_velocity_jump_resolved_into_small_steps_is_found_over_its_burst():
    """A jump of |Δq̇| = 10 m/s within ~0.1 ms on a motion of 8 m/s accelerating at 45 m/s²
    (A02's passage: an impulse ~1e5 m/s² against 45), sampled as an adaptive loop does:
    steps of 1 ms, then 5 µs through the burst."""
    velocity, acceleration = smoothed_step([0.0, -8.0, 0.0], [0.0, 0.0, 6.0], 1.0, 2e-5, [0.0, -45.0, 0.0])
    times = np.concatenate([np.arange(0.0, 0.9995, 1e-3), np.arange(0.9995, 1.0005, 5e-6),
                            np.arange(1.0005, 1.2, 1e-3)])
    alarms, watch = watch_over(times, velocity, acceleration)
    assert alarms, "the jump was not found"
    assert watch[JUMP_FROM] < 1.0 - 2 * 2e-5 and 1.0 < watch[JUMP_TO] < 1.0005     # the window holds the burst
    assert 0.5 * 8.0 < watch[JUMP_SIZE] <= 10.0 + 1e-9                              # of |v1 - v0| = 10


def test_a_velocity_jump_inside_one_step_is_found_by_the_trapezoidal_defect():
    """Two states 1 ms apart with ordinary accelerations whose velocities differ by 10 m/s."""
    velocity, acceleration = smoothed_step([0.0, -8.0, 0.0], [0.0, 0.0, 6.0], 1.0005, 2e-5, [0.0, -45.0, 0.0])
    alarms, watch = watch_over(np.arange(0.0, 1.2, 1e-3), velocity, acceleration)
    assert alarms and alarms[0] == pytest.approx(1.001)
    assert (watch[JUMP_FROM], watch[JUMP_TO]) == pytest.approx((1.0, 1.001))


def test_the_same_jump_is_no_branch_change_at_a_regular_configuration():
    """An impulse at a regular constraint Jacobian is an applied force's (a stiff contact): no alarm
    there; at a rank-deficient one, the alarm."""
    velocity, acceleration = smoothed_step([0.0, -8.0, 0.0], [0.0, 0.0, 6.0], 1.0005, 2e-5, [0.0, -45.0, 0.0])
    regular = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.5]])
    singular = np.array([[1.0, 0.0, 0.0], [1.0, 1e-3, 0.0]])       # σ_min/σ_max ≈ 5e-4
    found = {}
    for name, A in (("regular", regular), ("singular", singular)):
        watch = watch_array(3, 2)
        found[name] = [t for t in np.arange(0.0, 1.2, 1e-3)
                       if left_branch(watch, float(t), velocity(t), acceleration(t), A)]
    assert found["regular"] == [] and found["singular"][0] == pytest.approx(1.001)


def ratio(A, scale):
    """σ_min / max(σ_max, 1) of diag(scale) A by numpy's SVD."""
    sigma = np.linalg.svd(scale[:, None] * A, compute_uv=False)
    return sigma[-1] / max(sigma[0], 1.0)


@pytest.mark.parametrize("shape", [(1, 3), (3, 5), (5, 6), (6, 6), (8, 20)])
def test_singularity_is_the_singular_value_ratio_of_the_row_scaled_jacobian(shape):
    rng = np.random.default_rng(sum(shape))
    for conditioning in (1.0, 1e-2, 1e-5):
        A = rng.standard_normal(shape) * rng.uniform(0.1, 10.0, (shape[0], 1))
        A[-1] = A[0] + conditioning * A[-1] if shape[0] > 1 else A[-1]
        scale = 1.0 / np.linalg.norm(A, axis=1)
        assert singularity(A, scale) == pytest.approx(ratio(A, scale), rel=1e-6, abs=1e-9)
        assert singularity(A, scale / 10) == pytest.approx(ratio(A, scale / 10), rel=1e-6, abs=1e-9)


def test_a_row_that_vanishes_is_seen_through_the_first_states_row_scale():
    """The joint-coordinate slider-crank's one constraint row vanishes at 90°: scaled by its norm
    at the first state it shows the rank loss, scaled by its own norm it would not."""
    first = np.array([[0.8, -0.6]])
    watch = watch_array(2, 1)
    left_branch(watch, 0.0, np.array([1.0, 0.0]), np.array([0.0, 0.0]), first)
    assert singularity(1e-3 * first, 1.0 / np.linalg.norm(first, axis=1)) == pytest.approx(1e-3)
    assert watch[-1] == pytest.approx(1.0)                              # the row scale kept: 1/|row|


def test_singularity_without_rows_and_with_more_rows_than_columns():
    assert singularity(np.zeros((0, 4)), np.zeros(0)) == 1.0
    assert singularity(np.ones((3, 2)), np.ones(3)) == 0.0
    assert singularity(np.array([[1.0, 2.0], [0.0, 0.0]]), np.ones(2)) == 0.0


def test_kept_records_are_those_up_to_the_start_of_the_jump():
    watch = watch_array(1, 0)
    watch[JUMP_FROM] = 0.25
    T = np.array([0.0, 0.1, 0.2, 0.25, 0.3, 0.4])
    assert kept_records(T, 6, watch) == 4 and kept_records(T, 3, watch) == 3


# ----------------------------------------------------------------------------- IFToMM A02, N = 2
N = 2
FORMULATIONS = ("lagrange", "baumgarte", "penalty", "projection", "udwadia-kalaba", "matrix-r")


def off_branch(run) -> float:
    """Largest distance of the run's outputs from A02's physical branch, on which every crank
    has the same angle: max over outputs and i of |(B_i - A_i) - (B0 - A0)| (A_i = (i, 0))."""
    points = np.stack([np.column_stack([run[f"B{i}.x"] - i, run[f"B{i}.z"]]) for i in range(N + 1)], axis=1)
    return float(np.abs(points - points[:, :1]).max())


def b0_error(run) -> np.ndarray:
    """|B0 - B0_exact| at each output."""
    position, _ = exact_b0(run.t, N)
    return np.hypot(run["B0.x"] - position[:, 0], run["B0.z"] - position[:, 1])


@pytest.mark.parametrize("integrator", ["rk4", "rk45", "dop853"])
@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_a02_runs_that_say_success_stay_on_the_branch_and_failed_ones_keep_only_trustworthy_samples(formulation,
                                                                                                     integrator):
    """4 s of A02 (the cranks are horizontal at t = 0.714, 1.228, 2.657 and 3.171 s): projection
    and udwadia-kalaba with rk45 and dop853 used to say success after leaving the branch at
    2.657 s (B0 2 m off), lagrange dop853 returned samples 1.6 m off before failing.  Every
    returned sample must lie on the physical branch; a failed run says why, and its samples
    (up to the jump) follow the exact B0 to IFToMM's 1e-3 m.  (The accuracy of a successful
    run along the branch is not the watch's: matrix-r rk45 at the default tolerances ends 3.1e-2 m
    off after 20 s, on the branch to 1e-11 m.)"""
    model = cmbs.load("n-four-bar", N=N)
    options = dict(dt=1e-3, every=50) if integrator == "rk4" else dict(dt=0.05)
    run = cmbs.simulate(model, t_end=4.0, formulation=formulation, integrator=integrator, **options)
    assert off_branch(run) <= 1e-3, run.info["message"]
    if run.info["status"] == "success":
        assert run.t[-1] == pytest.approx(4.0)
    else:
        assert run.info["message"]
        assert b0_error(run).max() <= 1e-3


@pytest.mark.parametrize("formulation, integrator", [("projection", "rk45"), ("lagrange", "rk4")])
def test_a02_python_loop_ends_at_the_same_jump(formulation, integrator):
    """The Python loop watches as the compiled ones do: the same failure, its samples on the
    branch and on the exact B0 (the two loops round differently near the singular position, so
    the jump's instant may differ by a step; lagrange rk4's velocity grows tenfold there, which
    the message calls a divergence)."""
    model = cmbs.load("n-four-bar", N=N)
    options = dict(dt=1e-3, every=50) if integrator == "rk4" else dict(dt=0.05)
    runs = [cmbs.simulate(model, t_end=4.0, formulation=formulation, integrator=integrator, compiled=compiled,
                          **options) for compiled in (False, True)]
    for run in runs:
        assert run.info["status"] == "failed"
        assert run.info["message"].startswith(("the velocity jumped by", "the motion diverged: |q̇| grew"))
        assert off_branch(run) <= 1e-3 and b0_error(run).max() <= 1e-3
    assert runs[0].t[-1] == runs[1].t[-1]


def test_the_message_names_the_jump_and_what_to_try():
    run = cmbs.simulate(cmbs.load("n-four-bar", N=N), t_end=3.0, formulation="projection", integrator="rk45",
                        dt=0.05)
    message = run.info["message"]
    assert run.info["status"] == "failed"
    start, end = map(float, re.search(r"between t=(\S+) and t=(\S+),", message).groups())
    assert 2.6 < start < end < 2.7                        # the passage at 2.657 s
    assert run.t[-1] <= start
    assert "near a singular configuration" in message and "left its assembly branch" in message
    assert "generalized-alpha" in message and "projection_tolerance=1e-12" in message


@pytest.mark.parametrize("integrator, options", [
    ("rk4", dict(dt=1e-3, every=50)), ("rk4", dict(dt=1e-3, every=50, compiled=False)),
    ("dop853", dict(dt=0.05, rtol=1e-8, atol=1e-11)),
])
def test_a02_matrix_r_meets_high_precision_through_the_first_passages(integrator, options):
    """Matrix R through A02's first four passages (t = 0.714, 1.228, 2.657, 3.171 s): every
    output on the exact B0 to IFToMM's high precision (1e-3 m) and T + V constant to 1e-4 of its
    value (measured: 3e-7 to 2e-6 m, 5e-8 to 7e-8).  It used to stop at 0.97 s with RK4 and at
    2.91 s with DOP853 ("position recovery did not converge"): the partition chosen at a passage, where
    every partition's condition κ₂ is large, was kept until κ₂ grew 1.25-fold past that value,
    long after it had become a poor choice (docs/formulations.md, "Matrix R: when to choose the
    independent coordinates again")."""
    run = cmbs.simulate(cmbs.load("n-four-bar", N=N), t_end=4.0, formulation="matrix-r", integrator=integrator,
                        **options)
    assert run.info["status"] == "success", run.info["message"]
    assert run.t[-1] == pytest.approx(4.0)
    assert run.info.get("compiled", False) == options.get("compiled", True)
    assert b0_error(run).max() <= 1e-3
    energy = run["energy"]
    assert np.abs(energy - energy[0]).max() <= 1e-4 * abs(energy[0])


# ------------------------------------------------------------- A02, N = 2, the implicit integrators
@pytest.mark.parametrize("integrator", ["generalized-alpha", "trapezoidal"])
def test_a02_implicit_runs_that_say_success_follow_the_exact_motion_and_failed_ones_stop_at_the_jump(integrator):
    """4 s of A02 at 2 ms.  The trapezoidal rule (matrix R's independent coordinates) used to say
    success after leaving the branch at the first passage, 0.715 s, at every step from 1 to 10 ms
    (B0 2 m off, 78 % of the energy gone): it now fails there with the watch's message, its
    samples on the exact B0.  Generalized-α (index 3) keeps the branch, B0 within 1e-3 m."""
    run = cmbs.simulate(cmbs.load("n-four-bar", N=N), t_end=4.0, integrator=integrator, dt=2e-3, every=10)
    assert off_branch(run) <= 1e-3, run.info["message"]
    assert b0_error(run).max() <= 1e-3
    if integrator == "trapezoidal":
        assert run.info["status"] == "failed"
        message = run.info["message"]
        assert message.startswith("the velocity jumped by") and "left its assembly branch" in message
        assert "Try a smaller dt" in message and "project=True" not in message   # no drift projection here
        assert 0.7 < run.t[-1] < 0.716
    else:
        assert run.info["status"] == "success" and run.t[-1] == pytest.approx(4.0)


def test_a02_backward_euler_keeps_the_branch_its_damping_noted():
    """Backward Euler at 2 ms stays on the branch through the passages; its damping (the energy
    falls by 40 % of the largest kinetic energy in 4 s) takes B0 off the exact motion, which
    the note says."""
    run = cmbs.simulate(cmbs.load("n-four-bar", N=N), t_end=4.0, integrator="backward-euler", dt=2e-3, every=10)
    assert run.info["status"] == "success" and off_branch(run) <= 1e-3
    assert "backward-euler damps numerically by design" in run.info["note"]


@pytest.mark.parametrize("integrator, dt, t_end", [("trapezoidal", 2e-3, 1.0), ("generalized-alpha", 0.2, 4.0)])
def test_a02_implicit_python_loop_ends_at_the_same_jump(integrator, dt, t_end):
    """The implicit loop watches compiled and interpreted alike (the same code): the trapezoidal
    rule's jump at the first passage; generalized-α at 0.2 s steps (a third of the time between
    passages), whose velocity jumps by 0.76 |q̇| in the step to 4 s near the singular position.
    (Its samples stay on the parallelogram: an index-3 step keeps Φ = 0 from the last state,
    and no step from 1 ms to 0.25 s was seen to leave the branch; but 0.2 s resolves nothing,
    B0 is 1.4 m off before the jump.)"""
    model = cmbs.load("n-four-bar", N=N)
    runs = [cmbs.simulate(model, t_end=t_end, integrator=integrator, dt=dt, compiled=compiled)
            for compiled in (False, True)]
    for run in runs:
        assert run.info["status"] == "failed"
        assert run.info["message"].startswith("the velocity jumped by")
        assert off_branch(run) <= 1e-3
    assert runs[0].t[-1] == runs[1].t[-1] and runs[0].info["message"] == runs[1].info["message"]
