"""Simplified Newton in the implicit integrators' loop (cmbs.integrate.implicit.newton_steps): the
factored Newton matrix kept across iterations and steps while Newton contracts fast reaches the
solution of Newton's method proper (a matrix at every iterate) to Newton's tolerance, forms and
factors a matrix far less often, forms one afresh where a stiff spring calls for it, and fails
only where Newton's method proper fails, with its message."""


import numpy as np

import cmbs
from cmbs.integrate.implicit import generalized_alpha, integrate_index3

GRAVITY, LENGTH = 9.81, 1.0
TOLERANCE = 1e-10


def ring_residual(stiffness: float):
    """A unit mass on the circle |q| = LENGTH (Φ = q·q - L², A = 2qᵀ) under gravity and a linear
    spring of ``stiffness`` to the point (L, 0) of the circle: r = a + 2qλ - Q with
    Q = (0, -g) - k (q - (L, 0)); its tangents by hand, K_t = ∂r/∂q = (2λ + k) I, C_t = 0."""
    anchor = np.array([LENGTH, 0.0])

    def residual(t, q, v, a, lam):
        forces = np.array([0.0, -GRAVITY]) - stiffness * (q - anchor)
        return (a + 2.0 * q * lam[0] - forces, np.array([q @ q - LENGTH ** 2]), np.eye(2), 2.0 * q[None, :],
                np.zeros((2, 2)), (2.0 * lam[0] + stiffness) * np.eye(2))

    return residual


def ring_run(stiffness: float, q0: np.ndarray, step: float, t_end: float, keep_matrix: bool, **options):
    """Generalized-α (ρ∞ = 0.9) from rest at q0, the start's a and λ from M a + Aᵀλ = Q, A a = 0."""
    forces = np.array([0.0, -GRAVITY]) - stiffness * (q0 - np.array([LENGTH, 0.0]))
    kkt = np.block([[np.eye(2), 2.0 * q0[:, None]], [2.0 * q0[None, :], np.zeros((1, 1))]])
    start = np.linalg.solve(kkt, np.append(forces, 0.0))
    grid = np.linspace(0.0, t_end, int(round(t_end / step)) + 1)
    return integrate_index3(ring_residual(stiffness), q0, np.zeros(2), start[:2], start[2:], grid,
                            scheme=generalized_alpha(0.9), step=step, tolerance=TOLERANCE, keep_matrix=keep_matrix,
                            **options)


def test_kept_matrix_reaches_newtons_solution_to_the_tolerance():
    """The pendulum released from the horizontal, 2 s at 10 ms: the positions and velocities of
    the two runs differ by less than the error Newton's test lets each step leave (tolerance
    (1 + max|q|) in q, and in v for the kept matrix: its test), added up over the 200 steps;
    Newton's method proper forms and factors a matrix at every iterate, the kept one less than a
    quarter as often (measured: 92 against 400)."""
    kept, proper = (ring_run(0.0, np.array([LENGTH, 0.0]), 1e-2, 2.0, keep) for keep in (True, False))
    assert kept.status == proper.status == "success"
    steps = proper.counters["steps"]
    assert proper.counters["factorizations"] == proper.counters["newton_iterations"]
    assert 4 * kept.counters["factorizations"] < proper.counters["factorizations"]
    speed = np.abs(proper.y[:, 2:]).max()
    np.testing.assert_allclose(kept.y[:, :2], proper.y[:, :2], rtol=0, atol=steps * TOLERANCE * (1.0 + LENGTH))
    np.testing.assert_allclose(kept.y[:, 2:], proper.y[:, 2:], rtol=0, atol=steps * TOLERANCE * (1.0 + speed))
    assert np.abs(kept.y[:, :2] - proper.y[:, :2]).max() > 0.0      # the two methods did differ


def test_a_stiff_spring_forms_the_matrix_afresh_and_reaches_newtons_solution():
    """A spring of 10⁶ N/m at 0.1 s steps (ω h = 100): the matrix of a step's start no longer
    contracts at the next, so it is formed again within the steps (more factorisations than
    steps), and the run ends where Newton's method proper does."""
    kept, proper = (ring_run(1e6, np.array([0.0, -LENGTH]), 0.1, 1.0, keep) for keep in (True, False))
    assert kept.status == proper.status == "success"
    assert kept.counters["factorizations"] > kept.counters["steps"]
    np.testing.assert_allclose(kept.y[-1], proper.y[-1], rtol=0, atol=1e-8)


def test_a_failing_step_fails_as_newtons_method_proper_with_its_message():
    """Three iterations cannot settle the stiff spring's first step: the kept matrix's run tries it
    again by Newton's method proper, and fails with that method's message, time and correction."""
    kept, proper = (ring_run(1e6, np.array([0.0, -LENGTH]), 0.1, 1.0, keep, max_iterations=3)
                    for keep in (True, False))
    assert kept.status == proper.status == "failed"
    assert kept.message == proper.message
    assert kept.message.startswith("Newton iteration did not converge in 3 iterations at t=0.1 ")


def test_four_bar_factorizations_far_below_its_newton_iterations():
    """The compiled generalized-α on the four-bar, 1 s at 1 ms: the run info counts the Newton
    matrices formed and factored, fewer than one per twenty iterations, and the motion is the
    kinematic analysis's (the driven four-bar has one motion) to 1e-8."""
    model = cmbs.load("four-bar")
    run = cmbs.simulate(model, t_end=1.0, integrator="generalized-alpha", dt=1e-3)
    assert run.info["status"] == "success" and run.info["compiled"]
    assert 0 < 20 * run.info["factorizations"] < run.info["newton_iterations"]
    np.testing.assert_allclose(run.q, cmbs.kinematic_analysis(model, run.t).q, rtol=0, atol=1e-8)
