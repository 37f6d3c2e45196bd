"""URDF mimic joints coupled by a constraint row (``load_urdf(..., mimic=True)``, robot files'
``mimic = true``): the dynamics against Pinocchio's model of the same URDF with its mimic joints
(``buildModelFromUrdf(..., mimic=True)``: M and the bias forces of the independent joints), a
motion that keeps the coupling and the energy, the reactions' joint forces, and the errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import cmbs
from cmbs.errors import ModelError
from cmbs.inverse.robot_reactions import robot_reactions
from cmbs.model.urdf import load_urdf
from test_robot import ROBOTS, URDFS, needs_pinocchio, pinocchio

#: two pendulum links about y, the second coupled to the first: q2 = -2 q1 + 0.1
COUPLED_URDF = """<?xml version="1.0"?>
<robot name="coupled">
  <link name="base"/>
  <link name="upper"><inertial><origin xyz="0.05 0 -0.25" rpy="0.1 0 0"/><mass value="2"/>
    <inertia ixx="0.05" ixy="0.001" ixz="0" iyy="0.04" iyz="0.002" izz="0.01"/></inertial></link>
  <link name="lower"><inertial><origin xyz="0 0.02 -0.2"/><mass value="1.5"/>
    <inertia ixx="0.02" ixy="0" ixz="0.001" iyy="0.03" iyz="0" izz="0.005"/></inertial></link>
  <link name="side"><inertial><origin xyz="0.1 0 0"/><mass value="0.5"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.002"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="upper"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="10" velocity="5"/></joint>
  <joint name="j2" type="revolute"><parent link="upper"/><child link="lower"/>
    <origin xyz="0 0 -0.5"/><axis xyz="0 1 0"/>
    <limit lower="-6" upper="6" effort="10" velocity="5"/><mimic joint="j1" multiplier="-2" offset="0.1"/></joint>
  <joint name="j3" type="revolute"><parent link="lower"/><child link="side"/>
    <origin xyz="0 0 -0.4"/><axis xyz="1 0 0"/><limit lower="-3" upper="3" effort="10" velocity="5"/></joint>
</robot>
"""


@pytest.fixture
def coupled(tmp_path) -> Path:
    path = tmp_path / "coupled.urdf"
    path.write_text(COUPLED_URDF)
    return path


def _independent_dynamics(path: Path, model: cmbs.Model, rng: np.random.Generator):
    """At random states satisfying the mimic rows: cmbs's Lagrange accelerations (numpy's solve of
    [M Aᵀ; A 0] from cmbs's terms) of the joints that mimic none, and Pinocchio's
    M⁻¹(τ - b) of its model with mimic joints, τ the torques of those joints (none on the
    mimicking ones); yields both."""
    pm = pinocchio.buildModelFromUrdf(str(path), mimic=True)
    pd = pm.createData()
    rows = [name.removesuffix(".mimic") for name in model.constraint_names]
    free = [k for k, name in enumerate(model.coordinate_names) if name not in rows]
    slots = [pm.joints[pm.getJointId(model.coordinate_names[k])].idx_q for k in free]
    for _ in range(10):
        q, qd, u = np.zeros(model.n), np.zeros(model.n), np.zeros(model.n)
        q[free], qd[free], u[free] = rng.uniform(-1.5, 1.5, len(free)), rng.normal(size=len(free)), \
            rng.normal(scale=3.0, size=len(free))
        terms = model.evaluate(q, qd, 0.0, u)
        # the mimicking coordinates from the rows (linear: Φ = 0 and A q̇ = 0 solved for them)
        dependent = [model.coordinate_names.index(name) for name in rows]
        q[dependent] -= np.linalg.solve(terms.A[:, dependent], terms.phi)
        qd[dependent] = -np.linalg.solve(terms.A[:, dependent], terms.A[:, free] @ qd[free])
        terms = model.evaluate(q, qd, 0.0, u)
        assert np.abs(terms.phi).max() < 1e-14 and np.abs(terms.A @ qd).max() < 1e-13
        system = np.block([[terms.M, terms.A.T], [terms.A, np.zeros((model.m, model.m))]])
        solution = np.linalg.solve(system, np.concatenate([terms.Q, terms.gamma]))
        q_pin, v_pin, tau = np.zeros(pm.nq), np.zeros(pm.nv), np.zeros(pm.nv)
        q_pin[slots], v_pin[slots], tau[slots] = q[free], qd[free], u[free]
        expected = np.linalg.solve(pinocchio.crba(pm, pd, q_pin), tau - pinocchio.rnea(pm, pd, q_pin, v_pin,
                                                                                         np.zeros(pm.nv)))
        yield solution[:model.n][free], expected[slots], (q, qd, u, solution[:model.n], solution[model.n:])


@needs_pinocchio
@pytest.mark.parametrize("robot", ["coupled", "panda"])
def test_mimic_rows_give_pinocchios_mimic_dynamics(robot, coupled):
    """The coupled pendulum (multiplier -2, offset 0.1) and the Panda (its second finger mimics
    the first): the accelerations of the joints that mimic none equal those of Pinocchio's model
    with mimic joints, to 1e-10 relative, at 10 random states each."""
    path = coupled if robot == "coupled" else ROBOTS / URDFS["panda"]
    model = load_urdf(path, mimic=True)
    assert model.constraint_names == (("j2.mimic",) if robot == "coupled" else ("panda_finger_joint2.mimic",))
    for got, expected, _ in _independent_dynamics(path, model, np.random.default_rng(2)):
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10 * np.abs(expected).max())


def test_a_coupled_swing_keeps_the_coupling_and_the_energy(coupled):
    """The coupled pendulum released from rest at q1 = 0.6 (q2 = -1.1 on the coupling): 2 s with DOP853 at
    rtol 1e-10 keeps q2 = -2 q1 + 0.1 to 1e-9 and T + V to 1e-8 J, while the joints swing."""
    model = load_urdf(coupled, mimic=True)
    model = model.replace(q0=cmbs.assemble(model, np.array([0.6, -1.1, 0.2])))
    run = cmbs.simulate(model, t_end=2.0, dt=0.05, integrator="dop853", rtol=1e-10, atol=1e-12, compiled=False)
    assert run.info["status"] == "success"
    np.testing.assert_allclose(run.q[:, 1], -2.0 * run.q[:, 0] + 0.1, rtol=0, atol=1e-9)
    energy = model.energy_history(run.q, run.qd)
    assert np.abs(energy - energy[0]).max() < 1e-8
    assert np.ptp(run.q[:, 0]) > 0.5


def test_without_mimic_the_joint_has_a_coordinate_of_its_own(coupled):
    """The default (as Pinocchio's): no row, three free coordinates; the mimic is kept as data."""
    model = cmbs.load(str(coupled))
    assert model.m == 0 and model.n == 3
    assert model.parameters["joints"][1]["mimic"] == ("j1", -2.0, 0.1)


@needs_pinocchio
def test_reactions_count_the_mimic_transmission_as_joint_actuation(coupled):
    """With the coupling's multiplier λ, each joint's force along its axis is its torque u minus
    the row's generalized force (Aᵀλ): the coupling acts between the two joints."""
    model = load_urdf(coupled, mimic=True)
    for _, _, (q, qd, u, qdd, lam) in _independent_dynamics(coupled, model, np.random.default_rng(5)):
        result = robot_reactions(model, q, qd, qdd, lam, u)
        expected = u - model.evaluate(q, qd, 0.0, u).A.T @ lam
        got = [result["joint_forces"][name] for name in model.coordinate_names]
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10 * np.abs(u).max())


def test_mimic_mistakes_are_one_line_errors(tmp_path, coupled):
    bad = tmp_path / "bad.urdf"
    bad.write_text(COUPLED_URDF.replace('<mimic joint="j1"', '<mimic joint="j9"'))
    with pytest.raises(ModelError, match=r"joint 'j2': <mimic joint='j9'>: not a movable joint of the tree"):
        load_urdf(bad, mimic=True)
    bad.write_text(COUPLED_URDF.replace('multiplier="-2"', 'multiplier="two"'))
    with pytest.raises(ModelError, match="multiplier"):
        load_urdf(bad)
    robot_file = tmp_path / "coupled.toml"
    robot_file.write_text(f'[model]\nurdf = "{coupled}"\nmimic = "yes"\n')
    with pytest.raises(ModelError, match=r"coupled.toml: model: mimic must be true or false, got 'yes'"):
        cmbs.load(robot_file)
    robot_file.write_text(f'[model]\nurdf = "{coupled}"\nmimic = true\n')
    model = cmbs.load(robot_file)
    assert model.constraint_names == ("j2.mimic",)
    np.testing.assert_allclose(model.q0[1], -2.0 * model.q0[0] + 0.1, atol=1e-12)
