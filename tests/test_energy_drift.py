"""The energy check of a run: which models conserve T + V (Model.work_sources), the relative
drift info["energy_drift"] computed independently from the recorded motion, and the note when it
is large."""

import numpy as np
import pytest
import sympy as sp

import cmbs
from cmbs.cli import main
from cmbs.control.faults import mass_fault
from cmbs.model.equations import from_callables, from_sympy
from cmbs.model.natural import NaturalModelBuilder
from cmbs.simulate import ENERGY_NOTE, simulate
from cmbs.sweep import SweepResult, Variant, sweep


def _pendulum_with(**elements) -> cmbs.Model:
    """The 1 m pendulum of rod O-P, plus the given force, torque or spring."""
    builder = NaturalModelBuilder("pendulum-with")
    builder.add_point("O", 0.0, 0.0, fixed=True)
    builder.add_point("P", 1.0, 0.0)
    builder.add_point("W", 1.0, 1.0, fixed=True)
    builder.add_segment("rod", "O", "P", mass=1.0, com=(0.5, 0.0), inertia=1 / 12)
    builder.add_angle("phi", segment="rod")
    if "force" in elements:
        builder.add_force("push", point="P", fx=0.0, fz=elements["force"])
    if "torque" in elements:
        builder.add_torque("twist", angle="phi", torque=elements["torque"])
    if "damping" in elements:
        builder.add_spring("band", "P", "W", stiffness=5.0, damping=elements["damping"])
    return builder.build()


def _independent_drift(model: cmbs.Model, run: cmbs.Trajectory) -> float:
    """max |E - E0| / max T from the recorded states, T = ½ q̇ᵀ M(q) q̇ with M from the model."""
    kinetic = np.array([0.5 * qd @ model.mass_matrix(q) @ qd for q, qd in zip(run.q, run.qd)])
    energy = kinetic + np.array([model.potential_energy(q) for q in run.q])
    return float(np.abs(energy - energy[0]).max() / kinetic.max())


def test_work_sources_name_what_does_work():
    assert _pendulum_with().work_sources == ()
    assert _pendulum_with(force=0.0, torque="0").work_sources == ("torque 'twist'",)   # an expression is kept
    assert _pendulum_with(force="sin(t)").work_sources == ("force 'push'",)
    assert _pendulum_with(damping=0.0).work_sources == ()                 # a spring alone is in V
    assert _pendulum_with(damping=0.5).work_sources == ("damper 'band'",)
    driven = cmbs.load("four-bar")
    assert driven.work_sources == ("driver 'crank'",)
    assert driven.without_drivers().work_sources == ()
    assert cmbs.load("slider-crank-joint").work_sources == ()
    assert cmbs.load("chaplygin-sleigh").work_sources == ()                # shown symbolically (from_sympy)
    assert mass_fault(cmbs.load("pendulum"), "rod", factor=1.1).work_sources is None


def test_a_driver_of_a_constant_does_no_work():
    """Φ = q_c - c has Φ_t = 0: the human body with its hip held by two such drivers conserves
    T + V, in natural coordinates, joint coordinates and from SymPy alike; a moving driver does
    not."""
    assert cmbs.load("human", fixed_hip=True).work_sources == ()
    builder = NaturalModelBuilder("held")
    builder.add_point("O", 0.0, 0.0, fixed=True)
    builder.add_point("P", 1.0, 0.0)
    builder.add_segment("rod", "O", "P", mass=1.0, com=(0.5, 0.0), inertia=1 / 12)
    builder.add_angle("phi", segment="rod")
    builder.add_driver("phi", 0.2, name="hold")
    assert builder.build().work_sources == ()
    builder.add_driver("P.x", "cos(t)", name="swing")
    assert builder.build().work_sources == ("driver 'swing'",)
    from cmbs.model.joints import JointModelBuilder

    joint = JointModelBuilder("arm")
    joint.add_link("upper", parent=None, coordinate="a", length=1.0, mass=1.0, com=(0.5, 0.0), inertia=0.1)
    joint.add_link("lower", parent="upper", coordinate="b", origin=(1.0, 0.0), length=1.0, mass=1.0,
                   com=(0.5, 0.0), inertia=0.1)
    joint.add_driver("b", 0.3)
    assert joint.build().work_sources == ()
    x, z, t = sp.symbols("x z t")
    steady = from_sympy("steady", coordinates=[x, z], mass_matrix=sp.eye(2), forces=[0, -9.81], potential=9.81 * z,
                        constraints=[x - 0.5, x**2 + z**2 - 1], drivers=["phi[0]"], q0=[0.5, -0.8])
    assert steady.work_sources == ()
    moving = from_sympy("moving", coordinates=[x, z], mass_matrix=sp.eye(2), forces=[0, -9.81], potential=9.81 * z,
                        constraints=[x - 0.5 * sp.cos(t), x**2 + z**2 - 1], drivers=[0], q0=[0.5, -0.8])
    assert moving.work_sources == ("driver 'phi[0]'",)


def test_from_sympy_models_are_judged_by_their_power_balance():
    """P = q̇ᵀ(Q + ∂V/∂q) + ½ q̇ᵀṀq̇ (u = 0) must vanish identically: gravity with its potential,
    a central force with Coriolis terms in polar coordinates and the double pendulum in absolute
    angles (M(q), Q with its centrifugal terms) conserve T + V; damping, gravity without its
    potential and a moving constraint that is not a driver do work."""
    x, z, t, x_d, z_d = sp.symbols("x z t x_d z_d")
    circle = dict(coordinates=[x, z], mass_matrix=sp.diag(1.3, 1.3), constraints=[x**2 + z**2 - 0.49],
                  q0=[0.2, -0.67])
    assert from_sympy("p", forces=[0, -1.3 * 9.81], potential=1.3 * 9.81 * z, **circle).work_sources == ()
    forces = "forces (q̇ᵀ(Q + ∂V/∂q) + ½ q̇ᵀṀq̇ ≠ 0)"
    assert from_sympy("p", forces=[0, -1.3 * 9.81], **circle).work_sources == (forces,)
    assert from_sympy("p", forces=[-0.1 * x_d, -1.3 * 9.81 - 0.1 * z_d], potential=1.3 * 9.81 * z,
                      **circle).work_sources == (forces,)
    r, th = sp.symbols("r theta", positive=True)
    r_d, th_d = sp.symbols("r_d theta_d")
    polar = from_sympy("polar", coordinates=[r, th], mass_matrix=sp.diag(1.3, 1.3 * r**2),
                       forces=[1.3 * r * th_d**2 - 2.5 / r**2, -2 * 1.3 * r * r_d * th_d], potential=-2.5 / r,
                       q0=[1.0, 0.0])
    assert polar.work_sources == ()
    p1, p2, w1, w2 = sp.symbols("p1 p2 p1_d p2_d")
    coupling = sp.Rational(1, 2)
    double = from_sympy("double", coordinates=[p1, p2],
                        mass_matrix=sp.Matrix([[sp.Rational(4, 3), coupling * sp.cos(p1 - p2)],
                                               [coupling * sp.cos(p1 - p2), sp.Rational(1, 3)]]),
                        forces=[-coupling * sp.sin(p1 - p2) * w2**2 - 1.5 * 9.81 * sp.cos(p1),
                                coupling * sp.sin(p1 - p2) * w1**2 - 0.5 * 9.81 * sp.cos(p2)],
                        potential=1.5 * 9.81 * sp.sin(p1) + 0.5 * 9.81 * sp.sin(p2), q0=[0.3, 0.2])
    assert double.work_sources == ()
    moving = from_sympy("moving", coordinates=[x, z], mass_matrix=sp.eye(2), forces=[0, 0],
                        constraints=[x - sp.sin(t), x * z - 1], drivers=[], q0=[0.0, 1.0])
    assert moving.work_sources == ("rheonomic constraint 'phi[0]'",)
    driven = from_sympy("driven", coordinates=[x, z], mass_matrix=sp.eye(2), forces=[0, 0],
                        constraints=[x - sp.sin(t), x * z - 1], drivers=["phi[0]"], q0=[0.0, 1.0])
    assert driven.work_sources == ("driver 'phi[0]'",)


def test_energy_parts_agree_with_the_row_by_row_energies():
    model = _pendulum_with(damping=0.0)
    generator = np.random.default_rng(3)
    q, qd = generator.normal(size=(6, model.n)), generator.normal(size=(6, model.n))
    kinetic, potential = model.energy_parts(q, qd)
    np.testing.assert_allclose(kinetic, [model.kinetic_energy(a, b) for a, b in zip(q, qd)], rtol=1e-13)
    np.testing.assert_allclose(potential, [model.potential_energy(a) for a in q], rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("settings", [{}, {"integrator": "rk4", "dt": 0.05}, {"integrator": "rk4", "dt": 0.01,
                                                                                "formulation": "matrix-r"}])
def test_energy_drift_is_measured_on_conservative_runs(settings):
    model = _pendulum_with(damping=0.0)            # gravity and a spring: conservative
    run = simulate(model, t_end=2.0, **settings)
    assert run.info["energy_drift"] == pytest.approx(_independent_drift(model, run), rel=1e-9)


def test_a_large_drift_gets_a_note_and_a_small_one_none():
    model = cmbs.load("pendulum")
    accurate = simulate(model, t_end=2.0)
    coarse = simulate(model, t_end=2.0, integrator="rk4", dt=0.05)
    assert accurate.info["energy_drift"] < ENERGY_NOTE and "energy" not in accurate.info.get("note", "")
    assert coarse.info["energy_drift"] > ENERGY_NOTE          # measured 3.4e-3
    assert f"changed by {100 * coarse.info['energy_drift']:.2g} % of its largest kinetic energy" in coarse.info["note"]
    assert "smaller dt" in coarse.info["note"]
    python = simulate(model, t_end=2.0, integrator="rk4", dt=0.05, compiled=False)   # both notes, neither lost
    assert python.info["note"].startswith("Python loop: compiled=False; the energy T + V of this conservative model")
    damped = simulate(model, t_end=2.0, integrator="backward-euler", dt=0.01)
    assert damped.info["energy_drift"] > 0.1 and "backward-euler damps numerically" in damped.info["note"]


def _callable_pendulum(damping: float, conservative: bool) -> cmbs.Model:
    """The 1 m point pendulum (1 kg) in (x, z) from Python functions, with viscous damping."""
    return from_callables("callable-pendulum", coordinate_names=["x", "z"], mass_matrix=lambda q: np.eye(2),
                          forces=lambda q, qd, t, u: np.array([0.0, -9.81]) - damping * qd,
                          constraints=lambda q, t: np.array([q @ q - 1.0]),
                          jacobian=lambda q, t: np.array([2.0 * q]), gamma=lambda q, qd, t: np.array([-2.0 * qd @ qd]),
                          potential=lambda q: 9.81 * q[1], q0=[1.0, 0.0], conservative=conservative)


def test_a_from_callables_model_is_judged_when_its_author_states_it_conservative():
    assert _callable_pendulum(0.0, conservative=False).work_sources is None
    stated = _callable_pendulum(0.0, conservative=True)
    assert stated.work_sources == ()
    run = simulate(stated, t_end=2.0, integrator="rk4", dt=0.01)
    assert run.info["energy_drift"] == pytest.approx(_independent_drift(stated, run), rel=1e-9)
    assert run.info["energy_drift"] < ENERGY_NOTE and "changed by" not in run.info["note"]   # RK4, 10 ms: 2.3e-6
    wrong = simulate(_callable_pendulum(0.5, conservative=True), t_end=2.0, integrator="rk4", dt=0.01)
    assert wrong.info["energy_drift"] > 0.1                 # the damper's loss, against the statement
    assert "changed by" in wrong.info["note"]
    assert "energy_drift" not in simulate(_callable_pendulum(0.5, conservative=False), t_end=0.5).info


def test_runs_that_may_gain_or_lose_energy_are_not_judged():
    arm = cmbs.load("two-link-arm")                           # actuated, conservative without inputs
    assert "energy_drift" in simulate(arm, t_end=0.5).info
    assert "energy_drift" in simulate(arm, t_end=0.5, u=np.zeros(2)).info
    assert "energy_drift" not in simulate(arm, t_end=0.5, u=np.array([1.0, 0.0])).info
    damped = simulate(_pendulum_with(damping=2.0), t_end=2.0, integrator="rk4", dt=0.05)
    assert "energy_drift" not in damped.info and "energy" not in damped.info.get("note", "")
    driven = simulate(cmbs.load("four-bar"), t_end=0.5)
    assert "energy_drift" not in driven.info


def test_the_cli_prints_the_drift_and_the_note(capsys):
    assert main(["simulate", "pendulum", "--integrator", "rk4", "--dt", "0.05", "--t-end", "2"]) == 0
    out = capsys.readouterr().out
    assert "J (0.0034 of the largest kinetic energy)" in out
    assert "note: the energy T + V of this conservative model changed by 0.34 %" in out
    assert main(["simulate", "four-bar", "--t-end", "0.5"]) == 0           # driven: not judged
    assert "kinetic energy" not in capsys.readouterr().out


def test_describe_names_what_does_work(capsys):
    assert main(["describe", "four-bar"]) == 0
    assert "work done by driver 'crank'" in capsys.readouterr().out
    assert main(["describe", "pendulum"]) == 0
    assert "gravity and springs only: T + V is conserved with zero inputs" in capsys.readouterr().out
    assert main(["describe", "chaplygin-sleigh"]) == 0
    assert "T + V is conserved" in capsys.readouterr().out


def test_sweeps_report_each_variants_energy_drift(tmp_path):
    """The batched and process paths give the same drift, computed from the recorded outputs."""
    model = cmbs.load("four-bar").without_drivers()
    variants = [Variant(qd0=cmbs.velocities(model, model.q0, qd=np.eye(model.n)[-1] * speed), label=f"{speed}")
                for speed in (0.0, 0.5, 1.0)]
    batched = sweep(model, variants, t_end=2.0, dt=1e-2, every=5)
    serial = sweep(model, variants, t_end=2.0, dt=1e-2, every=5, batched=False, workers=1)
    assert batched.info["mode"] == "batched" and serial.info["mode"] == "processes"
    np.testing.assert_allclose(batched.energy_drift, serial.energy_drift, rtol=1e-6)
    for v in range(len(variants)):
        kinetic = [model.kinetic_energy(q, qd) for q, qd in zip(batched.q[v], batched.qd[v])]
        energy = batched.energy[v]
        assert batched.energy_drift[v] == pytest.approx(np.abs(energy - energy[0]).max() / max(kinetic), rel=1e-9)
    path = batched.save(tmp_path / "sweep.npz")
    np.testing.assert_array_equal(SweepResult.load(path).energy_drift, batched.energy_drift)
    with np.load(path) as data:                               # a file written before the drift was recorded
        older = {key: data[key] for key in data.files if key != "energy_drift"}
    np.savez(tmp_path / "older.npz", **older)
    assert np.isnan(SweepResult.load(tmp_path / "older.npz").energy_drift).all()


def _double_pendulum(lower_mass: float) -> cmbs.Model:
    """Two rods, 1 m, the upper of 1 kg, under gravity, released from the horizontal."""
    builder = NaturalModelBuilder("double", gravity=(0.0, -9.81))
    builder.add_point("O", 0.0, 0.0, fixed=True)
    builder.add_point("A", 1.0, 0.0)
    builder.add_point("B", 2.0, 0.0)
    for name, i, j, mass in (("upper", "O", "A", 1.0), ("lower", "A", "B", lower_mass)):
        builder.add_segment(name, i, j, mass=mass, com=(0.5, 0.0), inertia=mass / 12.0, length=1.0)
    return builder.build()


def test_a_sweeps_mass_factors_are_judged_on_the_changed_mechanisms_energy():
    """The variant with the lower rod 1.5 times heavier against the mechanism built with it:
    its recorded energies and drift are that mechanism's T + V on the recorded states."""
    nominal, heavy = _double_pendulum(1.0), _double_pendulum(1.5)
    result = sweep(nominal, [Variant(masses={"lower": 1.5})], t_end=1.0, dt=1e-2, integrator="rk4",
                   batched=False, workers=1)
    kinetic, potential = heavy.energy_parts(result.q[0], result.qd[0])
    np.testing.assert_allclose(result.energy[0], kinetic + potential, rtol=1e-12, atol=1e-12)
    expected = np.abs(kinetic + potential - kinetic[0] - potential[0]).max() / kinetic.max()
    assert result.energy_drift[0] == pytest.approx(expected, rel=1e-9)
    alone = simulate(heavy, t_end=1.0, dt=1e-2, integrator="rk4")     # the same motion, its own check
    np.testing.assert_allclose(result.q[0], alone.q, atol=1e-12)
    assert result.energy_drift[0] == pytest.approx(alone.info["energy_drift"], rel=1e-9)


def test_the_sweep_command_prints_the_drift_and_a_note(capsys):
    assert main(["sweep", "pendulum", "--speed", "P.z=0,-1", "--t-end", "2", "--dt", "0.05",
                 "--integrator", "rk4"]) == 0
    out = capsys.readouterr().out
    assert "drift  0.0034" in out and "note: 2 conservative variant(s) changed their energy" in out
