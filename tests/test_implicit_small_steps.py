"""The index-3 integrators (generalized-α, backward Euler) at small fixed steps: no step of the
loop is a sliver left by the rounding of the time (cmbs.integrate.implicit.step_to_output), and
none is shorter than dt at the end of a run (t_end a whole number of steps).  Either gave the
run a step whose index-3 equations fix the accelerations and multipliers to rounding errors
divided by h² or h: the pendulum at dt = 1e-4 s ended "success" with max|λ| 1.5e6 and its energy
off by 10.5 J, the note blaming generalized-α's damping.

Checked against the closed forms of the uniform rod of the library's ``pendulum`` (m = 1 kg,
L = 1 m, pinned at O, released from rest horizontal, V = 0 there): E = T + V = 0, and the
constraint force on the tip P (f_c = -Aᵀλ, along the rod) of magnitude

    |f_c| = (m/3) |v_P|² / L + (m g / 2) (-z_P / L)

(the radial equation of P, whose natural-coordinate mass is m/3 and generalized weight m g/2),
at most 1.5 m g (θ̇² = 3 g sin φ / L at the angle φ below the horizontal)."""

import numpy as np
import pytest

import cmbs
from cmbs.cli import main
from cmbs.errors import CmbsError
from cmbs.integrate.implicit import step_to_output
from cmbs.simulate import dissipated_only, output_times

MASS, GRAVITY, LENGTH = 1.0, 9.81, 1.0
#: The largest kinetic energy, m g L / 2 at the bottom, and the largest constraint force, 1.5 m g.
LARGEST_KINETIC, LARGEST_FORCE = MASS * GRAVITY * LENGTH / 2, 1.5 * MASS * GRAVITY
#: The largest angular velocity, at the bottom, and a bound on |d f_c/dt| ≤ 2.5 m g θ̇_max.
LARGEST_RATE = np.sqrt(3 * GRAVITY / LENGTH)
FORCE_RATE = 2.5 * MASS * GRAVITY * LARGEST_RATE
#: A bound on generalized-α's energy error over 10 s (T_run): its second-order error
#: (θ̇_max h)² θ̇_max T_run T_max ≈ 2.8e-5 J at h = 1e-4 s, and Newton's, which lets each step
#: leave a velocity error of tolerance (1 + max|v|) (1e-10 · 6.4, the kept matrix's test),
#: 1e5 steps adding up to 6.4e-5 m/s, m |v|max of it 2.4e-4 J: 2.7e-4 J below 1e-4 T_max = 4.9e-4 J.
ENERGY_BOUND = 1e-4 * LARGEST_KINETIC

RUNS = [("generalized-alpha", 1e-4, 10.0), ("generalized-alpha", 5e-5, 4.0),
        ("backward-euler", 1e-4, 10.0), ("backward-euler", 5e-5, 4.0)]


def closed_form_force(q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """|f_c| of the module docstring at each state (q, q̇) = (P, Ṗ)."""
    return MASS / 3 * (qd ** 2).sum(axis=1) / LENGTH + MASS * GRAVITY / 2 * (-q[:, 1] / LENGTH)


@pytest.mark.parametrize("integrator, dt, t_end", RUNS)
def test_pendulum_at_small_steps_keeps_its_energy_and_its_constraint_force(integrator, dt, t_end):
    """Generalized-α: |E - E0| within :data:`ENERGY_BOUND` and f_c within 1e-4 of 1.5 m g of the
    closed form (second order: (θ̇_max h)² 1.5 m g θ̇_max T_run = 2.3e-4 N at 1e-4 s, below
    1.5e-3 N); backward Euler, of first order and damped: E nowhere above its lowest value before
    by more than ENERGY_BOUND, f_c within h max|d f_c/dt| (its lag of less than a step); and
    both within the largest physical force."""
    run = cmbs.simulate("pendulum", t_end=t_end, integrator=integrator, dt=dt)
    assert run.info["status"] == "success", run.info["message"]
    energy, force = run.extras["energy"], run.extras["constraint_force"]
    magnitude = np.linalg.norm(force, axis=1)
    assert magnitude.max() <= LARGEST_FORCE * (1 + 1e-6)
    if integrator == "generalized-alpha":
        assert np.abs(energy).max() <= ENERGY_BOUND
        assert np.abs(magnitude - closed_form_force(run.q, run.qd)).max() <= 1e-4 * LARGEST_FORCE
        assert "note" not in run.info or "damps" not in run.info["note"]
    else:
        assert (energy - np.minimum.accumulate(energy)).max() <= ENERGY_BOUND
        assert energy.max() <= ENERGY_BOUND
        assert np.abs(magnitude - closed_form_force(run.q, run.qd)).max() <= dt * FORCE_RATE
    assert run.t[-1] == t_end and run.info["steps"] == round(t_end / dt)


@pytest.mark.parametrize("dt, t_end", [(1e-4, 10.0), (5e-5, 4.0), (1e-3, 20.0)])
def test_steps_to_the_outputs_are_equal_and_land_on_them(dt, t_end):
    """The loop's steps over the output grid (the times t + h of :func:`step_to_output`): every
    step is dt to rounding (no sliver: the rounding of t + h had left one of 7e-12 s at 7.0058 s
    for dt = 1e-4 s), and each output instant is reached exactly."""
    grid = output_times(t_end, dt)
    t, shortest, longest = 0.0, np.inf, 0.0
    for target in grid[1:]:
        while True:
            h, lands = step_to_output(t, target, dt)
            shortest, longest = min(shortest, h), max(longest, h)
            t = target if lands else t + h
            if lands:
                break
        assert t == target
    assert abs(shortest / dt - 1) < 1e-9 and abs(longest / dt - 1) < 1e-9      # 10 s / 1e-4 s: ulp(t)/dt < 2e-11


@pytest.mark.parametrize("integrator", ["generalized-alpha", "backward-euler"])
def test_a_t_end_that_is_no_whole_number_of_steps_is_refused(integrator, capsys):
    """The last step would be dt/500: generalized-α's λ there was 1.25 for an exact 0.061 at
    dt/100.  One line naming t_end and dt, exit status 2, before any work."""
    with pytest.raises(CmbsError, match=r"t_end = 1\.00002 s with dt = 0\.01 s"):
        cmbs.simulate("pendulum", t_end=1.00002, integrator=integrator, dt=0.01)
    assert main(["simulate", "pendulum", "--integrator", integrator, "--dt", "0.01", "--t-end", "1.00002"]) == 2
    error = capsys.readouterr().err.strip()
    assert "\n" not in error and "t_end = 1.00002 s with dt = 0.01 s" in error


def test_damping_explains_a_loss_only():
    """An energy that only falls (the most by 0.3 J, largest T 1 J) is what damping can explain;
    one that rises 0.2 J above an earlier low (0.2 of the largest T) is not."""
    kinetic = np.array([0.0, 1.0, 0.5, 0.8])
    assert dissipated_only(kinetic, np.array([0.0, -0.1, -0.3, -0.3]))
    assert not dissipated_only(kinetic, np.array([0.0, -0.1, 0.1, -0.3]))
