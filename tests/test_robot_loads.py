"""Applied loads of robots (cmbs.model.robot_loads): joint springs and dampers, URDF damping on
request, point forces and moments on links.

Against Pinocchio loaded from the same URDF: the accelerations equal ``aba`` with the springs'
and dampers' torques added to τ, and with the forces and moments given as Pinocchio's external
forces (``fext``, per joint in its local frame, converted here from the world force at the world
point by ``oMi.actInv``), on the UR5 and on test_robot.py's branching tree (a prismatic joint,
links fixed to movable ones); the joint reactions equal ``data.f`` of ``rnea`` with the same
``fext``.  Against closed forms: a pendulum on a torsional spring swings as ``A cos(ω t)``,
``ω = √(k/I)``, and with a damper decays as ``exp(-c t / (2 I))``.  Energy: T + V of a sprung run
kept, a damped run's loss equal to the dampers' work ``∫ Σ c q̇² dt``.  The robot files'
sections and their errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import cmbs
from cmbs.inverse.robot_reactions import robot_reactions
from cmbs.model.robot import JointSpring, LinkForce, LinkMoment
from cmbs.model.urdf import load_urdf
from test_robot import ROBOTS, TREE, URDFS, _pinocchio_state, _velocity_indices, needs_pinocchio, pinocchio

DOCS = Path(__file__).resolve().parents[1] / "docs" / "robots.md"

#: a pendulum about the vertical axis z (gravity does no work on it): its body 2 kg at 0.3 m from
#: the axis with izz = 0.04 kg m², so I = 0.04 + 2·0.3² = 0.22 kg m² about the axis; a massless
#: tip fixed to it, and URDF damping 0.5 N m s/rad
PENDULUM = """<?xml version="1.0"?>
<robot name="pendulum">
  <link name="base"/>
  <link name="arm"><inertial><origin xyz="0.3 0 0"/><mass value="2"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.04"/></inertial></link>
  <link name="tip"/>
  <joint name="hinge" type="revolute"><parent link="base"/><child link="arm"/>
    <origin xyz="0 0 0.5"/><axis xyz="0 0 1"/><dynamics damping="0.5" friction="0.1"/>
    <limit lower="-3" upper="3" effort="10" velocity="5"/></joint>
  <joint name="tip_joint" type="fixed"><parent link="arm"/><child link="tip"/><origin xyz="0.6 0 0"/></joint>
</robot>
"""
PENDULUM_INERTIA = 0.04 + 2.0 * 0.3**2


@pytest.fixture
def pendulum(tmp_path: Path) -> Path:
    path = tmp_path / "pendulum.urdf"
    path.write_text(PENDULUM)
    return path


def _robot(robot: str, folder: Path) -> str:
    if robot == "tree":
        path = folder / "tree.urdf"
        path.write_text(TREE)
        return str(path)
    return str(ROBOTS / URDFS[robot])


def _pinocchio_acceleration(model, pm, pd, q, v, tau, fext=None) -> np.ndarray:
    """Pinocchio's aba at the model's (q, q̇) with the joint torques τ (model's order), in the
    model's order."""
    q_pin, v_pin = _pinocchio_state(model, pm, q, v)
    index = _velocity_indices(model, pm)
    tau_pin = np.zeros(pm.nv)
    tau_pin[index] = tau
    a = pinocchio.aba(pm, pd, q_pin, v_pin, tau_pin) if fext is None else \
        pinocchio.aba(pm, pd, q_pin, v_pin, tau_pin, fext)
    return a[index]


def _fext(pm, pd, q_pin, loads) -> object:
    """Pinocchio's external forces of ``loads`` (link, force or moment as given, point in the
    link frame or None for a moment, True when given in the link's axes): each the spatial force
    about the world origin, (F, p × F) or (0, M) in world axes, moved into its joint's frame."""
    pinocchio.framesForwardKinematics(pm, pd, q_pin)
    fext = pinocchio.StdVec_Force()
    for _ in range(pm.njoints):
        fext.append(pinocchio.Force.Zero())
    for link, vector, point, in_link in loads:
        frame = pm.getFrameId(link)
        joint = pm.frames[frame].parentJoint
        placement = pd.oMf[frame]
        world = placement.rotation @ vector if in_link else np.asarray(vector, dtype=float)
        if point is None:
            spatial = pinocchio.Force(np.zeros(3), world)
        else:
            spatial = pinocchio.Force(world, np.cross(placement.act(np.asarray(point, dtype=float)), world))
        fext[joint] = fext[joint] + pd.oMi[joint].actInv(spatial)
    return fext


def _relative(value: np.ndarray, reference: np.ndarray) -> float:
    return float(np.abs(value - reference).max() / np.abs(reference).max())


# ------------------------------------------------------------------ against Pinocchio
@needs_pinocchio
@pytest.mark.parametrize("robot", ["ur5", "tree"])
def test_joint_springs_and_dampers_are_aba_of_the_effective_torques(robot, tmp_path):
    """A spring-damper on every movable joint (random k, rest, c; the tree's oblique prismatic
    joint too), at 10 random (q, q̇, τ): q̈ = aba(q, q̇, τ - k (q - rest) - c q̇) to 1e-10
    relative; without the springs q̈ differs by more than 1e-6 (the comparison can fail).  Each
    joint's force along its axis (robot_reactions) is then its torque plus its spring's."""
    path = _robot(robot, tmp_path)
    plain = load_urdf(path)
    rng = np.random.default_rng(21)
    k, rest, c = rng.uniform(1.0, 50.0, plain.n), rng.uniform(-1.0, 1.0, plain.n), rng.uniform(0.1, 5.0, plain.n)
    model = load_urdf(path, springs=[JointSpring(f"s{i}", name, k[i], rest[i], c[i])
                                     for i, name in enumerate(plain.coordinate_names)])
    pm = pinocchio.buildModelFromUrdf(path)
    pd = pm.createData()
    for _ in range(10):
        q, v, tau = rng.uniform(-2.0, 2.0, model.n), rng.normal(0.0, 2.0, model.n), rng.normal(0.0, 10.0, model.n)
        terms = model.evaluate(q, v, 0.0, tau)
        qdd = np.linalg.solve(terms.M, terms.Q)
        expected = _pinocchio_acceleration(model, pm, pd, q, v, tau - k * (q - rest) - c * v)
        assert _relative(qdd, expected) < 1e-10
        assert _relative(_pinocchio_acceleration(model, pm, pd, q, v, tau), expected) > 1e-6
        joint_forces = robot_reactions(model, q, v, qdd, np.zeros(0), tau)["joint_forces"]
        effective = tau - k * (q - rest) - c * v
        np.testing.assert_allclose([joint_forces[name] for name in model.coordinate_names], effective, rtol=0,
                                   atol=1e-10 * np.abs(effective).max())


#: per robot: forces (link, components, their values at t by numpy, point) and moments (link,
#: components, values); the tree's "hand" and "plate" are fixed to movable links by fixed joints with
#: turned origins, "left" hangs from the prismatic joint
LOADS = {
    "ur5": ([("forearm_link", ("3.0", "-2.0 + sin(3 * t)", 5.0), lambda t: [3.0, -2.0 + np.sin(3 * t), 5.0],
              (0.05, 0.1, -0.02)),
             ("tool0", (-4.0, 1.0, "2 * t"), lambda t: [-4.0, 1.0, 2 * t], (0.0, 0.0, 0.1))],
            [("wrist_2_link", (0.4, "-0.3 * cos(t)", 0.2), lambda t: [0.4, -0.3 * np.cos(t), 0.2])]),
    "tree": ([("hand", (2.0, -1.0, "1 + t"), lambda t: [2.0, -1.0, 1 + t], (0.03, -0.02, 0.05)),
              ("left", (0.5, "3 * sin(t)", -1.0), lambda t: [0.5, 3 * np.sin(t), -1.0], (0.1, 0, 0))],
             [("plate", ("0.2 * t", 0.5, -0.1), lambda t: [0.2 * t, 0.5, -0.1]),
              ("finger", (0.01, 0.02, -0.03), lambda t: [0.01, 0.02, -0.03])]),
}


@needs_pinocchio
@pytest.mark.parametrize("frame", ["world", "link"])
@pytest.mark.parametrize("robot", ["ur5", "tree"])
def test_point_forces_and_moments_are_aba_with_external_forces(robot, frame, tmp_path):
    """Forces at link points and moments on links (functions of t, along the world's or the
    links' axes), at 10 random (q, q̇, τ, t): q̈ = aba(q, q̇, τ, fext) to 1e-10 relative, and
    the joint reactions at (q, q̇, q̈, τ) equal Pinocchio's ``data.f`` after rnea(q, q̇, q̈, fext)
    (world axes, about the joint origins) to 1e-10 of the largest; without fext Pinocchio's q̈
    differs."""
    from test_robot_reactions import _pinocchio_joint_forces

    path = _robot(robot, tmp_path)
    forces, moments = LOADS[robot]
    loads = [LinkForce(f"f{i}", link, force, point, frame) for i, (link, force, _, point) in enumerate(forces)] + \
        [LinkMoment(f"m{i}", link, moment, frame) for i, (link, moment, _) in enumerate(moments)]
    model = load_urdf(path, loads=loads)
    assert model.work_sources == tuple(f"force 'f{i}'" for i in range(len(forces))) + \
        tuple(f"moment 'm{i}'" for i in range(len(moments)))
    pm = pinocchio.buildModelFromUrdf(path)
    pd = pm.createData()
    rng = np.random.default_rng(5)
    for _ in range(10):
        q, v, tau = rng.uniform(-2.0, 2.0, model.n), rng.normal(0.0, 2.0, model.n), rng.normal(0.0, 10.0, model.n)
        t = float(rng.uniform(0.0, 3.0))
        terms = model.evaluate(q, v, t, tau)
        qdd = np.linalg.solve(terms.M, terms.Q)
        q_pin, v_pin = _pinocchio_state(model, pm, q, v)
        fext = _fext(pm, pd, q_pin, [(link, np.array(value(t)), point, frame == "link")
                                     for link, _, value, point in forces]
                     + [(link, np.array(value(t)), None, frame == "link") for link, _, value in moments])
        expected = _pinocchio_acceleration(model, pm, pd, q, v, tau, fext)
        assert _relative(qdd, expected) < 1e-10
        assert _relative(_pinocchio_acceleration(model, pm, pd, q, v, tau), expected) > 1e-6

        index = _velocity_indices(model, pm)
        a_pin = np.zeros(pm.nv)
        a_pin[index] = qdd
        torques, transmitted = _pinocchio_joint_forces(pm, pd, q_pin, v_pin, a_pin, fext)
        np.testing.assert_allclose(torques[index], tau, rtol=0, atol=1e-10 * np.abs(tau).max())
        result = robot_reactions(model, q, v, qdd, np.zeros(0), tau, t)
        scale = max(np.abs(force).max() for force, _ in transmitted.values())
        for name, (force, moment) in transmitted.items():
            np.testing.assert_allclose(result["forces"][name], force, rtol=0, atol=1e-10 * scale)
            np.testing.assert_allclose(result["moments"][name], moment, rtol=0, atol=1e-10 * scale)


@needs_pinocchio
def test_urdf_damping_is_applied_on_request(tmp_path):
    """The UR5 with ``<dynamics damping="0.5"/>`` on every joint (Pinocchio reads it into
    ``model.damping``): with ``joint_damping=True`` (or ``joint_damping = true`` in a robot file)
    q̈ = aba(τ - d q̇) to 1e-10 relative and the dampers are work sources; without, q̈ = aba(τ)
    (today's behaviour, Pinocchio's aba ignoring the damping) and nothing does work."""
    path = tmp_path / "ur5_damped.urdf"
    path.write_text((ROBOTS / URDFS["ur5"]).read_text().replace('damping="0.0"', 'damping="0.5"'))
    robot_file = tmp_path / "damped.toml"
    robot_file.write_text(f'[model]\nurdf = "{path}"\njoint_damping = true\n')
    pm = pinocchio.buildModelFromUrdf(str(path))
    pd = pm.createData()
    damping = np.asarray(pm.damping)
    assert np.all(damping == 0.5)
    plain, damped, from_file = load_urdf(path), load_urdf(path, joint_damping=True), cmbs.load(robot_file)
    assert plain.work_sources == ()
    assert damped.work_sources == from_file.work_sources == tuple(f"damping of joint {name!r}"
                                                                  for name in plain.coordinate_names)
    rng = np.random.default_rng(8)
    for _ in range(5):
        q, v, tau = rng.uniform(-2.0, 2.0, 6), rng.normal(0.0, 2.0, 6), rng.normal(0.0, 10.0, 6)
        for model, torques in ((plain, tau), (damped, tau - damping * v), (from_file, tau - damping * v)):
            terms = model.evaluate(q, v, 0.0, tau)
            assert _relative(np.linalg.solve(terms.M, terms.Q), pinocchio.aba(pm, pd, q, v, torques)) < 1e-10


# ------------------------------------------------------------------ closed forms
def test_a_pendulum_on_a_torsional_spring_swings_at_its_natural_frequency(pendulum):
    """No gravity, k = 3 N m/rad about the rest angle 0.2 rad, from 0.5 rad at rest: I q̈ = -k (q -
    rest), so q = rest + 0.3 cos(ω t) with ω = √(k/I), period 2π√(I/k), over 4 s (2.4 periods) to
    1e-8 rad (DOP853 at rtol 1e-11); T + V = ½ k 0.3² throughout."""
    k, rest = 3.0, 0.2
    model = load_urdf(pendulum, gravity=(0.0, 0.0, 0.0), springs=[JointSpring("s", "hinge", k, rest)])
    assert model.work_sources == ()
    run = cmbs.simulate(model, t_end=4.0, dt=0.01, q0=np.array([0.5]), qd0=np.zeros(1), integrator="dop853",
                        rtol=1e-11, atol=1e-13)
    omega = np.sqrt(k / PENDULUM_INERTIA)
    np.testing.assert_allclose(run.q[:, 0], rest + 0.3 * np.cos(omega * run.t), rtol=0, atol=1e-8)
    energy = model.energy_history(run.q, run.qd)
    np.testing.assert_allclose(energy, 0.5 * k * 0.3**2, rtol=1e-9)
    assert run.info["energy_drift"] < 1e-8


def test_a_damped_pendulum_decays_as_the_closed_form(pendulum):
    """k = 3 N m/rad, c = 0.2 N m s/rad, from 0.3 rad at rest: q = A e^(-σ t) (cos ω_d t +
    (σ/ω_d) sin ω_d t), σ = c/(2I), ω_d = √(k/I - σ²), over 4 s to 1e-8 rad; the run is not judged
    by its energy (the damper does work) and carries no note."""
    k, c = 3.0, 0.2
    model = load_urdf(pendulum, gravity=(0.0, 0.0, 0.0), springs=[JointSpring("s", "hinge", k, damping=c)])
    assert model.work_sources == ("damper 's'",)
    run = cmbs.simulate(model, t_end=4.0, dt=0.01, q0=np.array([0.3]), qd0=np.zeros(1), integrator="dop853",
                        rtol=1e-11, atol=1e-13)
    sigma = c / (2.0 * PENDULUM_INERTIA)
    omega = np.sqrt(k / PENDULUM_INERTIA - sigma**2)
    expected = 0.3 * np.exp(-sigma * run.t) * (np.cos(omega * run.t) + sigma / omega * np.sin(omega * run.t))
    np.testing.assert_allclose(run.q[:, 0], expected, rtol=0, atol=1e-8)
    assert "energy_drift" not in run.info and "note" not in run.info


def test_urdf_damping_alone_slows_the_pendulum_exponentially(pendulum):
    """``joint_damping=True`` applies the URDF's damping d = 0.5: I q̈ = -d q̇, so q̇ = q̇0 e^(-d t/I)
    and q = q̇0 I/d (1 - e^(-d t/I)), to 1e-9 over 2 s; the friction stays data."""
    model = load_urdf(pendulum, gravity=(0.0, 0.0, 0.0), joint_damping=True)
    assert model.parameters["joints"][0]["friction"] == 0.1
    run = cmbs.simulate(model, t_end=2.0, dt=0.01, qd0=np.array([2.0]), integrator="dop853", rtol=1e-11, atol=1e-13)
    decay = np.exp(-0.5 * run.t / PENDULUM_INERTIA)
    np.testing.assert_allclose(run.qd[:, 0], 2.0 * decay, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.q[:, 0], 2.0 * PENDULUM_INERTIA / 0.5 * (1.0 - decay), rtol=0, atol=1e-9)


# ------------------------------------------------------------------ energy
UR5_JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
              "wrist_3_joint")
STIFFNESS = np.array([40.0, 60.0, 30.0, 5.0, 4.0, 2.0])
REST = np.array([0.1, -1.2, 1.0, -0.4, 0.6, 0.0])


@needs_pinocchio
@pytest.mark.parametrize("damped", [False, True])
def test_ur5_energy_with_springs_and_dampers(damped):
    """A UR5 swinging under gravity on joint springs for 2 s (DOP853 at rtol 1e-10): without
    dampers E = T + V_gravity + ½ Σ k (q - rest)² (V_gravity of the robot without springs, the
    springs' part by hand) is kept to 1e-8 of the largest T, and the run's energy check judges it;
    with dampers c the run is not judged (the dampers do work) and the energy lost, E(0) - E(t),
    equals the dampers' work ∫ Σ c q̇² dt (cubic spline through the outputs) to 1e-7 of it."""
    path = str(ROBOTS / URDFS["ur5"])
    damping = np.array([1.0, 2.0, 1.5, 0.3, 0.2, 0.1]) if damped else np.zeros(6)
    model = load_urdf(path, springs=[JointSpring(f"s{i}", name, STIFFNESS[i], REST[i], damping[i])
                                     for i, name in enumerate(UR5_JOINTS)])
    plain = load_urdf(path)
    run = cmbs.simulate(model, t_end=2.0, dt=0.005, q0=np.array([0.3, -1.0, 1.2, -0.5, 0.8, 0.1]),
                        qd0=np.array([0.5, -0.3, 0.8, 1.0, -0.6, 0.4]), integrator="dop853", rtol=1e-10, atol=1e-12)
    kinetic = np.array([plain.kinetic_energy(q, qd) for q, qd in zip(run.q, run.qd)])
    energy = kinetic + np.array([plain.potential_energy(q) + 0.5 * STIFFNESS @ (q - REST)**2 for q in run.q])
    np.testing.assert_allclose(model.energy_history(run.q, run.qd), energy, rtol=1e-12, atol=1e-12)
    assert np.ptp(run.q[:, 1]) > 0.1
    if not damped:
        assert model.work_sources == ()
        assert np.abs(energy - energy[0]).max() < 1e-8 * kinetic.max()
        assert run.info["energy_drift"] < 1e-8
        return
    from scipy.interpolate import CubicSpline

    assert model.work_sources == tuple(f"damper 's{i}'" for i in range(6))
    assert "energy_drift" not in run.info and "note" not in run.info
    work = CubicSpline(run.t, run.qd**2 @ damping).antiderivative()(run.t)
    assert work[-1] > 0.1 * kinetic.max()
    np.testing.assert_allclose(energy[0] - energy, work, rtol=0, atol=1e-7 * work[-1])


# ------------------------------------------------------------------ robot files
DOC_EXAMPLE = DOCS.read_text().split("### Joint springs, dampers, forces and moments")[1].split("```toml\n")[1] \
    .split("```")[0]


@needs_pinocchio
def test_the_documented_robot_file_is_aba_with_its_loads(tmp_path):
    """docs/robots.md's example (a spring-damper, a force that is a function of t at a point of a
    link, a moment along a link's axes) on the UR5: q̈ = aba(τ - k (q - rest) - c q̇, fext) at 5
    random states and times, to 1e-10 relative."""
    path = ROBOTS / URDFS["ur5"]
    robot_file = tmp_path / "ur5-loads.toml"
    robot_file.write_text(DOC_EXAMPLE.replace('urdf = "ur5_robot.urdf"', f'urdf = "{path}"'))
    model = cmbs.load(robot_file)
    assert model.work_sources == ("damper 'elbow'", "force 'push'", "moment 'twist'")
    pm = pinocchio.buildModelFromUrdf(str(path))
    pd = pm.createData()
    elbow = UR5_JOINTS.index("elbow_joint")
    rng = np.random.default_rng(2)
    for _ in range(5):
        q, v, tau = rng.uniform(-2.0, 2.0, 6), rng.normal(0.0, 2.0, 6), rng.normal(0.0, 10.0, 6)
        t = float(rng.uniform(0.0, 3.0))
        terms = model.evaluate(q, v, t, tau)
        torques = tau.copy()
        torques[elbow] -= 50.0 * (q[elbow] - 0.5) + 2.0 * v[elbow]
        fext = _fext(pm, pd, q, [("wrist_3_link", np.array([0.0, 0.0, -20.0 * np.sin(2.0 * t)]), (0.0, 0.1, 0.0),
                                  False), ("forearm_link", np.array([0.0, 0.0, 1.5]), None, True)])
        assert _relative(np.linalg.solve(terms.M, terms.Q), pinocchio.aba(pm, pd, q, v, torques, fext)) < 1e-10


ROBOT_FILE = """[model]
urdf = "pendulum.urdf"
gravity = [0.0, 0.0, 0.0]

[springs.s]
joint = "hinge"
stiffness = 3.0
rest = 0.2
damping = 0.1

[forces.f]
link = "tip"
point = [0.0, 0.1, 0.0]
force = [1.0, "sin(t)", 0.0]
frame = "link"

[moments.m]
link = "arm"
moment = [0.0, 0.0, "0.5 * t"]
"""


def test_a_pendulum_robot_file_gives_each_section_s_generalized_force(pendulum):
    """The pendulum's file: Q = -k (q - rest) - c q̇ + the tip force's moment about the axis + the
    moment's z component, by hand: the tip at 0.6 m along the arm's x axis, the force (1, sin t)
    along the arm's (x, y) at (0.6, 0.1) in the arm's frame: moment 0.6 sin t - 0.1 about z."""
    robot_file = pendulum.parent / "pendulum.toml"
    robot_file.write_text(ROBOT_FILE)
    model = cmbs.load(robot_file)
    assert model.parameters["springs"][0]["stiffness"] == 3.0
    for q, qd, t in ((0.3, 0.5, 0.7), (-1.2, -2.0, 2.5)):
        expected = -3.0 * (q - 0.2) - 0.1 * qd + (0.6 * np.sin(t) - 0.1) + 0.5 * t
        assert model.forces(np.array([q]), np.array([qd]), t)[0] == pytest.approx(expected, rel=1e-13)


@pytest.mark.parametrize("replace, replacement, expected", [
    ('joint = "hinge"', 'joint = "hinje"', "springs.s: joint: unknown joint 'hinje' (did you mean 'hinge'?)"),
    ('joint = "hinge"', 'joint = "tip_joint"', "springs.s: joint: 'tip_joint' is a fixed joint: it has no coordinate"),
    ("stiffness = 3.0", "stiffness = -3.0", "springs.s: stiffness must be a finite number >= 0, got -3.0"),
    ("damping = 0.1", "damping = -0.1", "springs.s: damping must be a finite number >= 0, got -0.1"),
    ("stiffness = 3.0", 'stiffness = "stiff"', "springs.s: stiffness must be a number, got 'stiff'"),
    ("stiffness = 3.0\nrest = 0.2\ndamping = 0.1", "rest = 0.2",
     "springs.s: stiffness and damping are both 0"),
    ('joint = "hinge"\n', "", "springs.s: missing key(s) 'joint'"),
    ("stiffness = 3.0", "stifness = 3.0", "springs.s: unknown key(s) 'stifness' (did you mean 'stiffness'?)"),
    ('link = "tip"', 'link = "tpi"', "forces.f: link: unknown link 'tpi' (did you mean 'tip'?)"),
    ('link = "tip"', 'link = "base"', "forces.f: link: 'base' does not move (it is the root or fixed to it)"),
    ('force = [1.0, "sin(t)", 0.0]', "force = [1.0, 2.0]",
     "forces.f: force must be a list of 3 numbers or expressions of t, got [1.0, 2.0]"),
    ('force = [1.0, "sin(t)", 0.0]', 'force = [1.0, "sin(", 0.0]', "forces.f.force.y: "),
    ("point = [0.0, 0.1, 0.0]", "point = [0.1]", "forces.f: point must be a list of 3 finite numbers, got [0.1]"),
    ('frame = "link"', 'frame = "body"', "forces.f: frame: unknown frame 'body'; frames: world, link"),
    ('frame = "link"', "frame = 1", "forces.f: frame must be a string (a name), got 1"),
    ('force = [1.0, "sin(t)", 0.0]\n', "", "forces.f: missing key(s) 'force'"),
    ('link = "arm"\nmoment', 'link = "arn"\nmoment', "moments.m: link: unknown link 'arn' (did you mean 'arm'?)"),
    ('moment = [0.0, 0.0, "0.5 * t"]', 'moment = [0.0, 0.0, "0.5 * t"]\npoint = [0.0, 0.0, 0.0]',
     "moments.m: unknown key(s) 'point'"),
    ('moment = [0.0, 0.0, "0.5 * t"]', 'moment = [0.0, 0.0, "0.5 * t", 1.0]',
     "moments.m: moment must be a list of 3 numbers or expressions of t"),
    ("gravity = [0.0, 0.0, 0.0]", "gravity = [0.0, 0.0, 0.0]\njoint_damping = 1",
     "model: joint_damping must be true or false, got 1"),
])
def test_robot_file_load_mistakes_are_one_line_errors(pendulum, replace, replacement, expected):
    """Each mistake in a spring, force or moment entry: one line naming the file, the entry and
    the field, before any assembly."""
    assert ROBOT_FILE.count(replace) == 1
    robot_file = pendulum.parent / "pendulum.toml"
    robot_file.write_text(ROBOT_FILE.replace(replace, replacement))
    with pytest.raises(cmbs.ModelError) as error:
        cmbs.load(robot_file)
    message = str(error.value)
    assert "\n" not in message and message.startswith(str(robot_file))
    assert expected in message


def test_a_python_function_load_gives_the_expression_s_force(pendulum):
    """A force component given as a Python callable (evaluated before the kernel call; the model
    then has no compiled kernel) gives the same Q as the same function as an expression: the
    force f(t) along the world's y at the tip, 0.6 m from the axis z along the arm turned by q,
    has the moment 0.6 cos(q) f(t) about it."""
    def pushed(component):
        return load_urdf(pendulum, loads=[LinkForce("f", "tip", (0.0, component, 0.0))])

    expression = pushed("2 * sin(t)")
    python = pushed(cmbs.PythonFunction(lambda t: 2.0 * np.sin(t)))
    assert python.equations.compiled_kernel() is None and expression.equations.compiled_kernel() is not None
    for model in (expression, python):
        assert model.forces(np.array([0.4]), np.array([0.3]), 0.9)[0] == pytest.approx(
            0.6 * np.cos(0.4) * 2.0 * np.sin(0.9), rel=1e-13)


def test_python_load_mistakes_name_the_element(pendulum):
    """The same checks from Python: repeated names, a negative URDF damping applied (naming the
    URDF and the joint), an element of the wrong kind."""
    def error(**changes) -> str:
        with pytest.raises(cmbs.ModelError) as raised:
            load_urdf(changes.pop("path", pendulum), **changes)
        return str(raised.value)

    spring = JointSpring("s", "hinge", 1.0)
    assert "spring 's': duplicate spring name" in error(springs=[spring, spring])
    force = LinkForce("f", "arm", (1.0, 0.0, 0.0))
    assert "force 'f': duplicate force name" in error(loads=[force, force])
    assert "a load is a LinkForce or a LinkMoment" in error(loads=[spring])
    assert "a spring is a JointSpring" in error(springs=[force])
    assert "force 'f': point must be 3 finite numbers" in error(loads=[LinkForce("f", "arm", (1, 0, 0), (0, np.nan, 0))])
    negative = pendulum.parent / "negative.urdf"
    negative.write_text(PENDULUM.replace('damping="0.5"', 'damping="-0.5"'))
    message = error(path=negative, joint_damping=True)
    assert message.startswith(str(negative)) and "joint 'hinge': <dynamics damping=-0.5> must be" in message
    assert load_urdf(negative).work_sources == ()          # kept as data when not applied
