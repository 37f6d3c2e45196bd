"""The projection formulation's one compiled solve with each of Aghili's three constraint inertia
matrices, against values computed here with numpy: the saddle-point system [M Aᵀ; A 0] at
regular states, the inertia systems of cmbs.dynamics.projection's docstring at redundant
constraints and a singular position; without constraints; with a constraint inertia matrix that
becomes singular in a run; and the compiled runs of each inertia against each other and Lagrange."""

from __future__ import annotations

import numpy as np
import pytest

import cmbs
from cmbs.cli import main
from cmbs.dynamics import Projection
from cmbs.dynamics.field import CompiledDynamics
from cmbs.errors import SingularSystemError
from cmbs.model.equations import from_callables
from cmbs.simulate import simulate
from test_dynamics import redundant_four_bar

INERTIAS = [{"inertia": "standard"}, {"inertia": "symmetric"}, {"inertia": "parameterised"},
            {"inertia": "parameterised", "mu": 0.3}]
#: natural coordinates with massless angles (semi-definite M; the closed chain by band LU), joint coordinates
REGULAR_MODELS = [("four-bar", {}), ("human", {}), ("chain", {"links": 14, "closed": True}),
                  ("slider-crank-joint", {"gravity": 9.81})]


def name_of(options: dict) -> str:
    return "-".join(str(value) for value in options.values())


def saddle_point(terms) -> tuple[np.ndarray, np.ndarray]:
    """(q̈, λ) of [M Aᵀ; A 0][q̈; λ] = [Q; γ] by numpy."""
    n, m = terms.A.shape[1], terms.A.shape[0]
    solution = np.linalg.solve(np.block([[terms.M, terms.A.T], [terms.A, np.zeros((m, m))]]),
                               np.concatenate([terms.Q, terms.gamma]))
    return solution[:n], solution[n:]


def inertia_system(model: cmbs.Model, terms, inertia: str, mu: float | None = None,
                   threshold: float = 1e-9) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q̈, λ, P) of Aghili's system with the constraint inertia ``inertia`` as
    cmbs.dynamics.projection's docstring writes it: A⁺ = (DA)⁺D with D the reciprocal row norms of
    A at q0 and singular values of DA up to ``threshold`` discarded, P = I - A⁺A, M̂ = M + s(I - P)
    (s = trace M(q0) / n) for a semi-definite M, μ = s by default; λ = -(Aᵀ)⁺(I - P)(Mq̈ - Q)."""
    n = model.n
    M0 = model.mass_matrix(model.q0)
    s = np.trace(M0) / n
    D = 1.0 / np.linalg.norm(model.jacobian(model.q0, 0.0), axis=1)
    U, sigma, Vt = np.linalg.svd(terms.A * D[:, None], full_matrices=False)
    kept = sigma > threshold
    pinv = (Vt[kept].T / sigma[kept]) @ U[:, kept].T * D[None, :]
    P = np.eye(n) - Vt[kept].T @ Vt[kept]
    I_P = np.eye(n) - P
    M, Q = terms.M, terms.Q
    M_hat = M + s * I_P if np.linalg.eigvalsh(M0)[0] < 1e-12 else M
    w = pinv @ terms.gamma
    if inertia == "standard":
        qdd = np.linalg.solve(M_hat + P @ M - M_hat @ P, P @ Q + M_hat @ w)
    elif inertia == "symmetric":
        qdd = np.linalg.solve(P @ M_hat @ P + I_P @ M_hat @ I_P, P @ Q + (np.eye(n) - 2.0 * P) @ M_hat @ w)
    else:
        mu = s if mu is None else mu
        qdd = np.linalg.solve(P @ M + mu * I_P, P @ Q + mu * w)
    return qdd, -pinv.T @ (I_P @ (M @ qdd - Q)), P


def close(value: np.ndarray, reference: np.ndarray, tolerance: float) -> None:
    np.testing.assert_allclose(value, reference, rtol=0, atol=tolerance * max(1.0, np.abs(reference).max()))


def regular_states(model: cmbs.Model, count: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """q0 moved off the constraints by 1e-3 (A still regular) with random velocities."""
    rng = np.random.default_rng(11)
    return [(model.q0 + 1e-3 * rng.normal(size=model.n), rng.normal(size=model.n)) for _ in range(count)]


@pytest.mark.parametrize("options", INERTIAS, ids=name_of)
@pytest.mark.parametrize("name, parameters", REGULAR_MODELS, ids=[name for name, _ in REGULAR_MODELS])
def test_each_inertia_has_the_saddle_point_solution_at_regular_states(name, parameters, options):
    """Where A has full row rank and nothing is discarded, every constraint inertia's system has
    the unique solution of M q̈ + Aᵀλ = Q, A q̈ = γ (cmbs.dynamics.projection._by_schur): the
    solver (Python loop, inverse dynamics) and the compiled field give it, λ and -Aᵀλ included."""
    model = cmbs.load(name, **parameters)
    solver = Projection(**options).bind(model)
    compiled = CompiledDynamics(model, Projection(**options))
    for q, qd in regular_states(model, 3):
        terms = model.evaluate(q, qd, 0.2)
        qdd, lam = saddle_point(terms)
        got = solver.accelerations(terms, q, qd, 0.2)
        close(got.qdd, qdd, 1e-9)
        close(got.lam, lam, 1e-9)
        close(got.constraint_force, -terms.A.T @ lam, 1e-9)
        field_qdd, field_lam = compiled.accelerations(q, qd, 0.2)
        close(field_qdd, qdd, 1e-9)
        close(field_lam, lam, 1e-9)


@pytest.mark.parametrize("options", INERTIAS, ids=name_of)
@pytest.mark.parametrize("name, parameters", REGULAR_MODELS, ids=[name for name, _ in REGULAR_MODELS])
def test_the_svd_path_of_each_inertia_has_the_saddle_point_solution_at_regular_states(name, parameters, options):
    """The SVD path alone (which the solve takes where A is not certified regular) with each
    inertia: the same saddle-point solution at regular states, M semi-definite or not."""
    from cmbs.dynamics.projection import _by_svd

    model = cmbs.load(name, **parameters)
    kernel = Projection(**options).bind(model).kernel
    for q, qd in regular_states(model, 2):
        terms = model.evaluate(q, qd, 0.2)
        expected_qdd, expected_lam = saddle_point(terms)
        qdd, lam = np.empty(model.n), np.empty(model.m)
        assert _by_svd(terms.M, terms.Q, terms.A, terms.gamma, kernel.row_scale, kernel.threshold, kernel.inertia,
                       kernel.mu, kernel.scale, kernel.semi_definite, qdd, lam)
        close(qdd, expected_qdd, 1e-8)
        close(lam, expected_lam, 1e-8)


def singular_slider_crank() -> tuple[cmbs.Model, np.ndarray, np.ndarray]:
    """The slider-crank (crank and rod of equal length) at θ1 = 90°, where A loses rank, moving."""
    model = cmbs.load("slider-crank")
    values = dict(zip(model.coordinate_names, model.q0))
    values.update({"A.x": 0.0, "A.z": 1.0, "C.x": 0.0, "theta1": np.pi / 2, "theta2": -np.pi})
    q = np.array([values[name] for name in model.coordinate_names])
    return model, q, np.random.default_rng(4).normal(size=model.n)


def redundant_state() -> tuple[cmbs.Model, np.ndarray, np.ndarray]:
    """The four-bar with its coupler constraint twice, moving on its constraints."""
    model = redundant_four_bar()
    return model, model.q0, cmbs.velocities(model, model.q0, qd=np.eye(model.n)[-1] * 1.5, fixed=["alpha"])


def chain_twice_state() -> tuple[cmbs.Model, np.ndarray, np.ndarray]:
    """A bent 7-link chain whose every link is constrained twice (14 rows of rank 7, M definite),
    moving on its constraints (bent: along a straight chain M maps range(Aᵀ) into itself, and
    the inertias' right-hand sides would not differ)."""
    from cmbs.model.natural import NaturalModelBuilder

    builder = NaturalModelBuilder("chain-twice", gravity=(0.0, -9.81))
    builder.add_point("P0", 0.0, 0.0, fixed=True)
    point = np.zeros(2)
    for k in range(1, 8):
        point = point + np.array([np.cos(-0.4 * k), np.sin(-0.4 * k)])
        builder.add_point(f"P{k}", *point)
        builder.add_segment(f"link{k}", f"P{k - 1}", f"P{k}", mass=1.0, com=(0.5, 0.0), inertia=1 / 12, length=1.0)
        builder.add_segment(f"link{k}-again", f"P{k - 1}", f"P{k}", mass=0.0, length=1.0)
    model = builder.build()
    return model, model.q0, cmbs.velocities(model, model.q0, qd=np.random.default_rng(6).normal(size=model.n))


@pytest.mark.parametrize("options", INERTIAS, ids=name_of)
@pytest.mark.parametrize("state, semi_definite", [(redundant_state, True), (singular_slider_crank, True),
                                                  (chain_twice_state, False)],
                         ids=["redundant", "singular", "chain-twice"])
def test_each_inertia_where_a_loses_rank_solves_its_own_system(state, semi_definite, options):
    """Redundant constraints and a singular position, natural coordinates with massless angles
    (semi-definite M) or without (the doubled chain): the SVD discards directions, the
    saddle-point system is singular, and the solve is the inertia's own system written here from
    the module's formulas.  Its q̈ satisfies the projected equations P(Mq̈ - Q) = 0; with
    consistent γ (redundant constraints) also Aq̈ = γ."""
    model, q, qd = state()
    terms = model.evaluate(q, qd, 0.0)
    assert (np.linalg.eigvalsh(terms.M)[0] < 1e-12) == semi_definite
    assert np.linalg.matrix_rank(terms.A) < model.m
    got = Projection(**options).bind(model).accelerations(terms, q, qd, 0.0)
    qdd, lam, P = inertia_system(model, terms, options["inertia"], options.get("mu"))
    close(got.qdd, qdd, 1e-9)
    close(got.lam, lam, 1e-9)
    inertial = terms.M @ got.qdd
    close(P @ (inertial - terms.Q), np.zeros(model.n), 1e-9 * max(np.abs(inertial).max(), np.abs(terms.Q).max()))
    if state is not singular_slider_crank:
        close(terms.A @ got.qdd, terms.gamma, 1e-9)
    field_qdd, field_lam = CompiledDynamics(model, Projection(**options)).accelerations(q, qd, 0.0)
    close(field_qdd, qdd, 1e-9)
    close(field_lam, lam, 1e-9)


@pytest.mark.parametrize("options", INERTIAS, ids=name_of)
def test_without_constraints_each_inertia_is_m_inverse_q(options):
    """The joint-coordinate two-link arm (m = 0): P = I, and every system is M q̈ = Q."""
    model = cmbs.load("two-link-arm-joint")
    assert model.m == 0
    rng = np.random.default_rng(2)
    q, qd = rng.normal(size=model.n), rng.normal(size=model.n)
    terms = model.evaluate(q, qd, 0.0)
    expected = np.linalg.solve(terms.M, terms.Q)
    got = Projection(**options).bind(model).accelerations(terms, q, qd, 0.0)
    close(got.qdd, expected, 1e-12)
    assert got.lam.shape == (0,)
    field_qdd, _ = CompiledDynamics(model, Projection(**options)).accelerations(q, qd, 0.0)
    close(field_qdd, expected, 1e-12)


def particle_losing_its_mass() -> cmbs.Model:
    """A particle on the line z = 0 pushed along x by a unit force, whose x-mass max(1 - x, 0) is
    exactly zero from x = 1 on: the motion the constraint allows then has no mass, and every
    constraint inertia matrix is singular.  From ẍ = 1 / (1 - x), x reaches 1 at t = √(π/2) =
    1.2533 s (tests/test_compiled_solves.py)."""
    return from_callables("particle-losing-its-mass", coordinate_names=["x", "z"],
                          mass_matrix=lambda q: np.diag([max(1.0 - q[0], 0.0), 1.0]),
                          forces=lambda q, qd, t, u: np.array([1.0, -9.81]),
                          constraints=lambda q, t: np.array([q[1]]), jacobian=lambda q, t: np.array([[0.0, 1.0]]),
                          gamma=lambda q, qd, t: np.zeros(1), q0=[0.0, 0.0])


@pytest.mark.parametrize("inertia", ["standard", "symmetric", "parameterised"])
def test_a_singular_constraint_inertia_matrix_fails_the_run_with_the_message(inertia):
    model = particle_losing_its_mass()
    message = f"the projection's {inertia} constraint inertia matrix is singular: a motion the constraints allow"
    run = simulate(model, t_end=2.0, integrator="rk4", dt=1e-2, formulation="projection",
                   formulation_options={"inertia": inertia})
    assert run.info["status"] == "failed" and 1.25 <= run.t[-1] < 1.26
    assert run.info["message"].startswith("model 'particle-losing-its-mass' at t=1.25") and message in \
        run.info["message"], run.info["message"]
    q = np.array([1.5, 0.0])
    with pytest.raises(SingularSystemError, match=message):
        Projection(inertia=inertia).bind(model).accelerations(model.evaluate(q, np.zeros(2), 0.0), q, np.zeros(2),
                                                              0.0)


@pytest.mark.parametrize("options", INERTIAS[1:], ids=name_of)
@pytest.mark.parametrize("integrator", ["rk4", "dop853"])
def test_every_inertia_runs_compiled_and_moves_as_the_standard_one_and_lagrange(integrator, options):
    """The four-bar (regular throughout) for 2 s: the run is compiled (no Python-loop note) and its
    motion and multipliers are those of the standard inertia and of Lagrange's equations."""
    model = cmbs.load("four-bar").without_drivers()
    settings = dict(t_end=2.0, integrator=integrator, dt=1e-3, rtol=1e-10, atol=1e-10)
    run = simulate(model, formulation="projection", formulation_options=options, **settings)
    assert run.info["compiled"] and "note" not in run.info and run.info["status"] == "success"
    for reference in (simulate(model, formulation="projection", **settings),
                      simulate(model, formulation="lagrange", **settings)):
        assert reference.info["compiled"] and reference.t.shape == run.t.shape
        np.testing.assert_allclose(run.q, reference.q, rtol=0, atol=1e-9)
        np.testing.assert_allclose(run["lam"], reference["lam"], rtol=1e-7, atol=1e-7)


def test_the_cli_runs_the_symmetric_inertia_compiled(capsys):
    assert main(["simulate", "four-bar", "--undriven", "--formulation", "projection", "--option",
                 "inertia=symmetric", "--integrator", "rk4", "--t-end", "0.2"]) == 0
    out = capsys.readouterr().out
    assert "projection + rk4, success" in out and "Python loop" not in out


def test_the_solver_builds_its_kernel_once_and_the_compiled_loops_use_it():
    model = cmbs.load("four-bar")
    for inertia in ("standard", "symmetric", "parameterised"):
        formulation = Projection(inertia=inertia)
        solver = formulation.bind(model)
        assert formulation.compiled(solver, model) is solver.kernel
        assert solver.kernel.inertia == ("standard", "symmetric", "parameterised").index(inertia)
    assert Projection(inertia="parameterised", mu=0.3).bind(model).kernel.mu == 0.3
    solver = Projection(inertia="parameterised").bind(model)
    assert solver.kernel.mu == pytest.approx(np.trace(model.mass_matrix(model.q0)) / model.n)
