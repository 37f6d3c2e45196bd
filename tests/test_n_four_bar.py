"""The IFToMM A02 N-four-bar of the library and its exact motion (cmbs.library.n_four_bar).

References are independent of the code under test: the model's own constraints, Jacobian, mass
matrix and potential evaluated at the parallelogram state built here from (θ, θ̇); the energy
integral of the 1-DOF reduction solved by quadrature for the time of the first singular passage.
"""

import math

import numpy as np
import pytest
from scipy.integrate import quad

import cmbs
from cmbs.cli import main
from cmbs.errors import ModelError
from cmbs.library.n_four_bar import MAX_N, crank_angle, exact_b0, n_four_bar
from cmbs.trajectory import Trajectory

G = 9.81


def parallelogram_state(model: cmbs.Model, N: int, theta: float, omega: float) -> tuple[np.ndarray, np.ndarray]:
    """(q, q̇) of the model with every crank at angle θ turning at θ̇: B_i = (i + cos θ, sin θ),
    Ḃ_i = θ̇ (-sin θ, cos θ) (L = 1 m), placed by coordinate name."""
    values = {}
    for i in range(N + 1):
        values[f"B{i}.x"] = (i + math.cos(theta), -omega * math.sin(theta))
        values[f"B{i}.z"] = (math.sin(theta), omega * math.cos(theta))
    q = np.array([values[name][0] for name in model.coordinate_names])
    qd = np.array([values[name][1] for name in model.coordinate_names])
    return q, qd


def first_passage_time(N: int) -> float:
    """Time at which the cranks first become horizontal (θ: π/2 → 0), from the energy integral
    θ̇² = 1 + (2C/I)(1 - sin θ) of the reduction (θ̇(0) = -1, θ̇ < 0 throughout), by quadrature."""
    inertia, moment = (N + 1) / 3 + N, G * ((N + 1) / 2 + N)
    return quad(lambda theta: 1.0 / math.sqrt(1.0 + 2.0 * moment / inertia * (1.0 - math.sin(theta))),
                0.0, math.pi / 2, epsabs=1e-13, epsrel=1e-13)[0]


def b0_error(run: Trajectory, N: int) -> tuple[float, float]:
    """Largest distance of the run's B0 from the exact B0, and of its velocity, over the outputs."""
    position, velocity = exact_b0(run.t, N)
    return (float(np.hypot(run["B0.x"] - position[:, 0], run["B0.z"] - position[:, 1]).max()),
            float(np.hypot(run.qd[:, run.names.index("B0.x")] - velocity[:, 0],
                           run.qd[:, run.names.index("B0.z")] - velocity[:, 1]).max()))


@pytest.mark.parametrize("N", [1, 2, 5])
def test_sizes_and_one_dof_at_the_start_n_plus_one_when_the_cranks_are_horizontal(N):
    model = cmbs.load("n-four-bar", N=N)
    assert (model.n, model.m) == (2 * N + 2, 2 * N + 1)
    assert model.total_mass == pytest.approx(2 * N + 1)
    assert cmbs.constraint_report(model, model.q0).dof == 1
    horizontal, _ = parallelogram_state(model, N, 0.0, 0.0)
    assert np.abs(model.constraints(horizontal)).max() < 1e-14
    assert cmbs.constraint_report(model, horizontal).dof == N + 1


@pytest.mark.parametrize("N", [1, 3])
def test_start_state_is_the_benchmarks(N):
    """q0: cranks vertical, couplers horizontal at y = 1; q̇0: every B_i at (1, 0) m/s, A q̇0 = 0."""
    model = cmbs.load("n-four-bar", N=N)
    q, qd = parallelogram_state(model, N, math.pi / 2, -1.0)
    assert np.abs(model.constraints(model.q0)).max() < 1e-12
    assert np.abs(model.q0 - q).max() < 1e-12
    assert np.abs(model.jacobian(model.q0) @ model.qd0).max() < 1e-12
    assert np.abs(model.qd0 - qd).max() < 1e-12
    assert model.parameters["N"] == N


@pytest.mark.parametrize("N, message", [
    (0, "positive integer"), (-3, "positive integer"), (2.5, "whole number"), ("3", "whole number"),
    (True, "whole number"), (MAX_N + 1, f"at most {MAX_N}"),
])
def test_bad_n_is_one_clear_model_error(N, message):
    with pytest.raises(ModelError, match=message):
        cmbs.load("n-four-bar", N=N)


def test_the_builder_refuses_a_flag_for_n():
    with pytest.raises(ModelError, match="positive integer"):
        n_four_bar(N=True)


@pytest.mark.parametrize("N", [2, 40])
def test_exact_motion_conserves_the_models_energy(N):
    """T + V of the model (its mass matrix and potential) at the exact parallelogram state stays
    at its value at (q0, q̇0) over 20 s (20 singular passages)."""
    model = cmbs.load("n-four-bar", N=N)
    start = model.energy(model.q0, model.qd0)
    times = np.linspace(0.0, 20.0, 401)
    theta, omega = crank_angle(times, N)
    energies = [model.energy(*parallelogram_state(model, N, a, w)) for a, w in zip(theta, omega)]
    assert np.abs(np.array(energies) - start).max() < 1e-9 * abs(start)
    assert theta[-1] < -6 * math.pi        # the cranks turned round several times, through θ = 0, -π, ...


@pytest.mark.parametrize("N", [2, 40])
def test_exact_motion_reaches_the_first_singular_passage_at_the_quadrature_time(N):
    t1 = first_passage_time(N)
    theta, omega = crank_angle(np.array([0.0, t1]), N)
    assert theta[0] == math.pi / 2 and omega[0] == -1.0
    assert abs(theta[1]) < 1e-9
    position, velocity = exact_b0(np.array([0.0, t1]), N)
    assert np.abs(position[0] - [0.0, 1.0]).max() < 1e-15 and np.abs(velocity[0] - [1.0, 0.0]).max() < 1e-15
    assert np.abs(position[1] - [1.0, 0.0]).max() < 1e-9


def test_simulation_before_the_first_passage_follows_the_exact_motion():
    """Lagrange (the default formulation), rk45 at tight tolerances, up to 0.6 s (the first
    passage is at 0.72 s for N = 2): B0 and its velocity within 1e-6."""
    assert first_passage_time(2) > 0.7
    run = cmbs.simulate(cmbs.load("n-four-bar"), t_end=0.6, dt=0.05, rtol=1e-10, atol=1e-12)
    assert run.info["status"] == "success"
    position_error, velocity_error = b0_error(run, 2)
    assert position_error < 1e-6 and velocity_error < 1e-6


def test_generalized_alpha_keeps_the_branch_through_singular_passages():
    """Generalized-α at h = 1 ms over 3 s: three passages (0.72 s, 1.22 s, 2.6 s for N = 2);
    B0 within IFToMM high precision (1e-3 m) of the exact motion at every 0.05 s output."""
    run = cmbs.simulate(cmbs.load("n-four-bar"), t_end=3.0, integrator="generalized-alpha", dt=1e-3, every=50)
    theta, _ = crank_angle(run.t, 2)
    assert theta[-1] < -math.pi                      # passed θ = 0 and θ = -π
    assert run.info["status"] == "success"
    assert b0_error(run, 2)[0] < 1e-3


def test_cli_simulates_n_four_bar_with_an_uppercase_parameter(tmp_path, capsys):
    out = tmp_path / "nfb.npz"
    assert main(["simulate", "n-four-bar", "--param", "N=3", "--t-end", "0.3", "--dt", "0.05", "--rtol", "1e-10",
                 "--atol", "1e-12", "--out", str(out)]) == 0
    run = Trajectory.load(out)
    assert tuple(run.names) == tuple(f"B{i}.{axis}" for i in range(4) for axis in "xz")
    assert b0_error(run, 3)[0] < 1e-6
    assert main(["simulate", "n-four-bar", "--param", "N=0", "--t-end", "0.3"]) == 2
    assert "N (the number of four-bar loops) must be a positive integer, got 0" in capsys.readouterr().err


@pytest.mark.parametrize("formulation, options", [
    ("projection", {"inertia": "standard"}), ("projection", {"inertia": "symmetric"}),
    ("projection", {"inertia": "parameterised"}), ("udwadia-kalaba", {}),
])
def test_index_one_formulations_keep_the_branch_through_twenty_passages_with_tight_drift_projection(formulation,
                                                                                                   options):
    """Projection (each inertia) and Udwadia-Kalaba, RK4 at h = 1 ms with coordinate and velocity
    projection after every step to max |Φ| < 1e-12, over the benchmark's 20 s (20 singular
    passages, the first at 0.72 s): B0 within IFToMM high precision (1e-3 m) of the exact motion
    at every 0.05 s output and T + V constant to 1e-4 of its value (measured 1e-7 to 1e-6 m,
    energy 1e-9 to 2e-8 of max T).  With the default drift-projection tolerance 1e-10 the same
    runs leave the branch (B0 2e-3 to 1e-2 m off after 12-16 s; docs/formulations.md)."""
    run = cmbs.simulate(cmbs.load("n-four-bar"), t_end=20.0, formulation=formulation, formulation_options=options,
                        integrator="rk4", dt=1e-3, every=50, project=True, projection_tolerance=1e-12)
    theta, _ = crank_angle(run.t, 2)
    assert theta[-1] < -6 * math.pi                  # the cranks turned round several times
    assert run.info["status"] == "success" and run.t[-1] == pytest.approx(20.0)
    assert b0_error(run, 2)[0] < 1e-3
    energy = run["energy"]
    assert np.abs(energy - energy[0]).max() <= 1e-4 * abs(energy[0])
