"""Joint reactions of robots (cmbs.inverse.robot_reactions): the forces RNEA transmits through each
joint against Pinocchio's (``data.f`` after ``rnea``, with external forces for a closed loop), the
closure wrenches against the rows' generalized force (virtual work), and ``cmbs inverse
--reactions`` on a driven UR5."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import cmbs
from cmbs.inverse import joint_reaction_history
from cmbs.inverse.robot_reactions import robot_reactions
from test_robot import ROBOTS, URDFS, needs_pinocchio, pinocchio
from test_robot_closures import CLOSURES, _made_up_tree, _ur5_file


def _pinocchio_joint_forces(pm, pd, q, v, a, fext=None):
    """τ and, per joint name, Pinocchio's transmitted force and moment about the joint origin
    (``data.f`` is in the joint's frame) turned into world axes."""
    tau = pinocchio.rnea(pm, pd, q, v, a) if fext is None else pinocchio.rnea(pm, pd, q, v, a, fext)
    local = [pd.f[i].copy() for i in range(pm.njoints)]
    pinocchio.forwardKinematics(pm, pd, q)
    world = {pm.names[i]: (pd.oMi[i].rotation @ local[i].linear, pd.oMi[i].rotation @ local[i].angular)
             for i in range(1, pm.njoints)}
    return tau, world


@needs_pinocchio
@pytest.mark.parametrize("robot", ["ur5", "panda"])
def test_open_tree_reactions_are_pinocchios_rnea_forces(robot):
    """At 20 random (q, q̇, q̈) with the torques τ = rnea(q, q̇, q̈): every joint's force and moment
    equal Pinocchio's ``data.f`` (in world axes) and the joint forces equal τ, to 1e-12 of the
    largest force (measured 1e-14 on the UR5)."""
    path = str(ROBOTS / URDFS[robot])
    model = cmbs.load(path)
    pm = pinocchio.buildModelFromUrdf(path)
    pd = pm.createData()
    assert list(pm.names[1:]) == list(model.coordinate_names)
    rng = np.random.default_rng(11)
    for _ in range(20):
        q, v, a = rng.uniform(-2, 2, model.n), rng.normal(size=model.n), rng.normal(size=model.n)
        tau, expected = _pinocchio_joint_forces(pm, pd, q, v, a)
        result = robot_reactions(model, q, v, a, np.zeros(0), tau)
        scale = max(np.abs(force).max() for force, _ in expected.values())
        for name, (force, moment) in expected.items():
            np.testing.assert_allclose(result["forces"][name], force, rtol=0, atol=1e-12 * scale)
            np.testing.assert_allclose(result["moments"][name], moment, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose([result["joint_forces"][name] for name in model.coordinate_names], tau, rtol=0,
                                   atol=1e-12 * scale)


def _dynamic_state(model, rng):
    """A random (q, q̇, u, λ) and q̈ from the equations of motion M q̈ + Aᵀλ = Q (numpy's solve):
    the balance the reactions rest on, whatever λ (here not the constraint's own: the identity
    checked holds for every λ, so rank-deficient closures are covered too)."""
    q, qd, u = rng.uniform(-1.5, 1.5, model.n), rng.uniform(-2, 2, model.n), rng.normal(scale=5.0, size=model.n)
    lam = rng.normal(scale=5.0, size=model.m)
    terms = model.evaluate(q, qd, 0.0, u)
    return q, qd, u, np.linalg.solve(terms.M, terms.Q - terms.A.T @ lam), lam


@pytest.mark.parametrize("kind", CLOSURES)
def test_closure_wrenches_do_the_work_of_the_constraint_forces(kind):
    """A tree closed by each kind of closure, at 5 random states, λ and q̈ with M q̈ + Aᵀλ = Q:
    each joint's force along its axis is the joint torque u alone.  The joint forces
    are Sᵀ(Σ inertial wrenches - Σ closure wrenches) over its subtree; with M q̈ + Aᵀλ = u - b
    that is u exactly when the closure wrenches' generalized force is -Aᵀλ (the rows' A, itself
    checked against finite differences in tests/test_robot_closures.py)."""
    model = _made_up_tree([CLOSURES[kind]])
    rng = np.random.default_rng(3)
    for _ in range(5):
        q, qd, u, qdd, lam = _dynamic_state(model, rng)
        result = robot_reactions(model, q, qd, qdd, lam, u)
        joint_forces = [result["joint_forces"][name] for name in model.coordinate_names]
        np.testing.assert_allclose(joint_forces, u, rtol=0, atol=1e-10 * np.abs(u).max())
        assert set(result["closures"]) == set(model.constraint_names)


@needs_pinocchio
def test_a_ur5_holding_a_ground_point_against_pinocchio_with_the_closure_force(tmp_path):
    """The UR5's tool0 held at a ground point (a point closure: 3 rows), assembled, moving with
    the Lagrange accelerations under random torques: the closure force -λ on tool0, given to
    Pinocchio's RNEA as an external force of the last joint, gives Pinocchio's joint forces equal
    to the reactions and its τ equal to the torques u, to 1e-10 of the largest force."""
    path = ROBOTS / URDFS["ur5"]
    base = cmbs.load(str(path))
    q_guess = np.array([0.3, -1.2, 1.5, -0.8, 1.1, 0.4])
    rotation, origin = cmbs.model.robot.frame_placement(base, q_guess, "tool0")
    robot_file = tmp_path / "holding.toml"
    robot_file.write_text(f'[model]\nurdf = "{path}"\n\n[closures.hold]\nkind = "point"\nlink_a = "tool0"\n'
                          f'link_b = "ground"\npoint_b = [{float(origin[0])!r}, {float(origin[1])!r}, {float(origin[2])!r}]\n\n'
                          "[initial_positions]\n" + "".join(f"{name} = {float(value)!r}\n" for name, value in
                                                              zip(base.coordinate_names, q_guess)))
    model = cmbs.load(robot_file)
    assert model.m == 3 and np.abs(model.constraints(model.q0)).max() < 1e-12
    pm = pinocchio.buildModelFromUrdf(str(path))
    pd = pm.createData()
    tool = pm.getFrameId("tool0")
    wrist = pm.frames[tool].parentJoint
    rng = np.random.default_rng(5)
    q = model.q0
    for _ in range(3):
        qd = cmbs.velocities(model, q, qd=rng.normal(size=model.n), fixed=model.coordinate_names[:3])
        u = rng.normal(scale=10.0, size=model.n)
        terms = model.evaluate(q, qd, 0.0, u)
        system = np.block([[terms.M, terms.A.T], [terms.A, np.zeros((3, 3))]])
        solution = np.linalg.solve(system, np.concatenate([terms.Q, terms.gamma]))
        qdd, lam = solution[:6], solution[6:]
        result = robot_reactions(model, q, qd, qdd, lam, u)

        pinocchio.framesForwardKinematics(pm, pd, q)
        joint = pd.oMi[wrist]
        point = pd.oMf[tool].translation
        force = -lam                                    # on tool0, world axes
        fext = pinocchio.StdVec_Force()
        for _ in range(pm.njoints):
            fext.append(pinocchio.Force.Zero())
        fext[wrist] = pinocchio.Force(joint.rotation.T @ force, joint.rotation.T @ np.cross(point - joint.translation,
                                                                                            force))
        tau, expected = _pinocchio_joint_forces(pm, pd, q, qd, qdd, fext)
        scale = max(np.abs(f).max() for f, _ in expected.values())
        np.testing.assert_allclose(tau, u, rtol=0, atol=1e-10 * scale)
        for name, (force_j, moment_j) in expected.items():
            np.testing.assert_allclose(result["forces"][name], force_j, rtol=0, atol=1e-10 * scale)
            np.testing.assert_allclose(result["moments"][name], moment_j, rtol=0, atol=1e-10 * scale)
        np.testing.assert_allclose(result["closures"]["hold.x"], -lam[0])


@needs_pinocchio
def test_cmbs_inverse_reactions_of_a_driven_ur5(tmp_path, capsys):
    """``cmbs inverse FILE --reactions``: the joint forces it writes are the driver forces (the
    torques), and the forces and moments are written per joint; joint_reaction_history gives the
    same."""
    from cmbs.cli import main

    out = tmp_path / "reactions.npz"
    robot_file = _ur5_file(Path(tmp_path))
    assert main(["inverse", str(robot_file), "--t-end", "0.5", "--dt", "0.25", "--reactions", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "moment on elbow_joint" in printed and "joint force wrist_3_joint" in printed
    with np.load(out) as saved:
        torques = saved["driver_forces"]
        for i, name in enumerate(cmbs.load(robot_file).coordinate_names):
            np.testing.assert_allclose(saved[f"joint force {name}"], torques[:, i], rtol=0,
                                       atol=1e-10 * np.abs(torques).max())
        assert saved["reaction on shoulder_lift_joint"].shape == (3, 3)
    model = cmbs.load(robot_file)
    history = joint_reaction_history(model, cmbs.inverse_dynamics(model, np.array([0.0, 0.25])).motion)
    assert history["moments"]["elbow_joint"].shape == (2, 3)
