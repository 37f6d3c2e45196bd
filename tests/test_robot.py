"""Spatial joint-coordinate trees from URDF files against Pinocchio loaded from the same files:
mass matrix (CRBA), bias forces, forward (ABA) and inverse (RNEA) dynamics, frame placements and
Jacobians; energy conservation of a free swing; one-line errors on bad files.

Pinocchio's coordinates: a revolute or prismatic joint has one (at ``idx_q``); a continuous joint
(Pinocchio's unbounded revolute, kinova's joints 1, 4 and 6) has two, (cos θ, sin θ), and one
velocity (at ``idx_v``): :func:`_pinocchio_state` converts.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import cmbs
from helpers import example_robots
from cmbs.errors import CmbsError
from cmbs.model.robot import frame_jacobian, frame_placement

try:
    import pinocchio
except ImportError:
    pinocchio = None


ROBOTS = example_robots()
needs_pinocchio = pytest.mark.skipif(pinocchio is None or ROBOTS is None,
                                     reason="the comparisons need pinocchio (pip 'pin') and example-robot-data")
URDFS = {
    "ur5": "ur_description/urdf/ur5_robot.urdf",                 # 6 revolute
    "panda": "panda_description/urdf/panda.urdf",                # 7 revolute, 2 prismatic fingers, fixed joints
    "z1": "z1_description/urdf/z1.urdf",                         # 7 revolute about x, y and z axes
    "kinova": "kinova_description/robots/kinova.urdf",           # 3 continuous, 3 revolute
}
SAMPLES = 100

# A branching tree made to exercise what the robots above do not: inertial frames turned by rpy with
# full inertia tensors, fixed joints with rpy between movable ones (their masses merged), a mass
# fixed to the ground, oblique revolute and prismatic axes, a continuous joint, a massless end
# frame, and joints listed out of tree order.
TREE = """<?xml version="1.0"?>
<robot name="tree">
  <link name="world"/>
  <link name="pedestal"><inertial><origin xyz="0 0 0.1"/><mass value="5"/>
    <inertia ixx="0.2" ixy="0" ixz="0" iyy="0.2" iyz="0" izz="0.1"/></inertial></link>
  <link name="torso"><inertial><origin xyz="0.01 0.02 0.1" rpy="0.3 0.5 -0.7"/><mass value="3"/>
    <inertia ixx="0.1" ixy="0.01" ixz="-0.02" iyy="0.12" iyz="0.015" izz="0.08"/></inertial></link>
  <link name="plate"><inertial><origin xyz="0.03 -0.01 0.02" rpy="-0.2 0.1 0.9"/><mass value="0.7"/>
    <inertia ixx="0.01" ixy="0.001" ixz="0" iyy="0.02" iyz="-0.002" izz="0.015"/></inertial></link>
  <link name="left"><inertial><origin xyz="0 0.05 0" rpy="0.5 0 0"/><mass value="0.4"/>
    <inertia ixx="0.002" ixy="0" ixz="0.0003" iyy="0.003" iyz="0" izz="0.0025"/></inertial></link>
  <link name="right"><inertial><origin xyz="0.1 0 0" rpy="0 0.4 0.2"/><mass value="1.2"/>
    <inertia ixx="0.004" ixy="0.0005" ixz="0" iyy="0.02" iyz="0.001" izz="0.02"/></inertial></link>
  <link name="hand"><inertial><origin xyz="0.02 0.01 0" rpy="1.0 -0.3 0.1"/><mass value="0.5"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.0012" iyz="0.0001" izz="0.0009"/></inertial></link>
  <link name="finger"><inertial><origin xyz="0 0 0.03" rpy="0 0 0.3"/><mass value="0.1"/>
    <inertia ixx="0.0001" ixy="0" ixz="0" iyy="0.0001" iyz="0" izz="0.00005"/></inertial></link>
  <link name="marker"/>
  <joint name="finger_joint" type="revolute"><parent link="hand"/><child link="finger"/>
    <origin xyz="0.05 0 0.01" rpy="0.2 0.3 0.1"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="mount" type="fixed"><parent link="world"/><child link="pedestal"/>
    <origin xyz="0.1 -0.2 0.3" rpy="0.2 -0.1 0.4"/></joint>
  <joint name="waist" type="revolute"><parent link="pedestal"/><child link="torso"/>
    <origin xyz="0 0 0.2" rpy="0.1 0.2 0.3"/><axis xyz="0.6 0 0.8"/>
    <limit lower="-3" upper="3" effort="100" velocity="2"/></joint>
  <joint name="plate_mount" type="fixed"><parent link="torso"/><child link="plate"/>
    <origin xyz="0.05 0 0.3" rpy="0 1.0 0.5"/></joint>
  <joint name="left_slide" type="prismatic"><parent link="plate"/><child link="left"/>
    <origin xyz="0 0.1 0" rpy="0.4 0 0"/><axis xyz="0 0.6 -0.8"/>
    <limit lower="-0.5" upper="0.5" effort="10" velocity="1"/></joint>
  <joint name="right_turn" type="continuous"><parent link="plate"/><child link="right"/>
    <origin xyz="0 -0.1 0.05" rpy="0 0 -0.6"/><axis xyz="1 0 0"/></joint>
  <joint name="wrist_fixed" type="fixed"><parent link="right"/><child link="hand"/>
    <origin xyz="0.2 0 0" rpy="-0.5 0.2 0.7"/></joint>
  <joint name="marker_mount" type="fixed"><parent link="finger"/><child link="marker"/>
    <origin xyz="0 0 0.06" rpy="0.3 0 0"/></joint>
</robot>
"""


@pytest.fixture(scope="module")
def tree_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("tree") / "tree.urdf"
    path.write_text(TREE)
    return path


def _pair(robot: str, tree_file: Path) -> tuple[cmbs.Model, object, object]:
    path = str(tree_file if robot == "tree" else ROBOTS / URDFS[robot])
    model = cmbs.load(path)
    reference = pinocchio.buildModelFromUrdf(path)
    return model, reference, reference.createData()


def _pinocchio_state(model: cmbs.Model, reference: object, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray,
                                                                                                   np.ndarray]:
    """Pinocchio's (q, v) for the model's (q, q̇), joint by joint by name (module docstring)."""
    q_pin, v_pin = np.zeros(reference.nq), np.zeros(reference.nv)
    for k, name in enumerate(model.coordinate_names):
        joint = reference.joints[reference.getJointId(name)]
        assert joint.nv == 1
        if joint.nq == 2:
            q_pin[joint.idx_q:joint.idx_q + 2] = np.cos(q[k]), np.sin(q[k])
        else:
            q_pin[joint.idx_q] = q[k]
        v_pin[joint.idx_v] = v[k]
    return q_pin, v_pin


def _velocity_indices(model: cmbs.Model, reference: object) -> np.ndarray:
    return np.array([reference.joints[reference.getJointId(name)].idx_v for name in model.coordinate_names])


def _states(model: cmbs.Model, seed: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """SAMPLES random (q, q̇, τ, q̈), seeded."""
    rng = np.random.default_rng(seed)
    n = model.n
    return [(rng.uniform(-np.pi, np.pi, n), rng.normal(0.0, 2.0, n), rng.normal(0.0, 10.0, n),
             rng.normal(0.0, 5.0, n)) for _ in range(SAMPLES)]


def _relative(value: np.ndarray, reference: np.ndarray) -> float:
    return float(np.linalg.norm(value - reference) / np.linalg.norm(reference))


@needs_pinocchio
@pytest.mark.parametrize("robot", [*URDFS, "tree"])
def test_dynamics_match_pinocchio(robot: str, tree_file: Path) -> None:
    """M(q) vs crba, Q(q, q̇, 0) vs -rnea(q, q̇, 0), q̈ from M q̈ = Q(q, q̇, τ) (Lagrange, m = 0)
    vs aba, and τ = M q̈ - Q(q, q̇, 0) vs rnea(q, q̇, q̈): each to 1e-10 of the reference's norm."""
    model, reference, data = _pair(robot, tree_file)
    rows = _velocity_indices(model, reference)
    assert model.m == 0 and model.n_u == model.n == rows.size
    solver = cmbs.formulation("lagrange").bind(model)
    worst = dict(mass=0.0, bias=0.0, forward=0.0, inverse=0.0)
    for q, qd, tau, qdd in _states(model, seed=len(robot)):
        q_pin, v_pin = _pinocchio_state(model, reference, q, qd)
        mass = pinocchio.crba(reference, data, q_pin)
        mass = np.triu(mass) + np.triu(mass, 1).T
        terms = model.evaluate(q, qd, 0.0, tau)
        M, Q = terms.M.copy(), terms.Q.copy()
        worst["mass"] = max(worst["mass"], _relative(M, mass[np.ix_(rows, rows)]))
        bias = pinocchio.rnea(reference, data, q_pin, v_pin, np.zeros(reference.nv))[rows]
        Q0 = model.forces(q, qd)
        worst["bias"] = max(worst["bias"], _relative(Q0, -bias))
        tau_pin = np.zeros(reference.nv)
        tau_pin[rows] = tau
        forward = pinocchio.aba(reference, data, q_pin, v_pin, tau_pin)[rows]
        worst["forward"] = max(worst["forward"], _relative(solver.accelerations(terms, q, qd, 0.0).qdd, forward))
        qdd_pin = np.zeros(reference.nv)
        qdd_pin[rows] = qdd
        inverse = pinocchio.rnea(reference, data, q_pin, v_pin, qdd_pin)[rows]
        worst["inverse"] = max(worst["inverse"], _relative(M @ qdd - Q0, inverse))
    print(f"{robot}: worst relative errors vs Pinocchio over {SAMPLES} states: "
          + ", ".join(f"{key} {value:.1e}" for key, value in worst.items()))
    assert max(worst.values()) < 1e-10, worst


@needs_pinocchio
@pytest.mark.parametrize("robot", [*URDFS, "tree"])
def test_frames_match_pinocchio(robot: str, tree_file: Path) -> None:
    """Every link frame's rotation and origin vs framesForwardKinematics, its 6 x n Jacobian vs
    getFrameJacobian(LOCAL_WORLD_ALIGNED), to 1e-12."""
    model, reference, data = _pair(robot, tree_file)
    rows = _velocity_indices(model, reference)
    links = model.point_names
    assert set(links) == {frame.name for frame in reference.frames if frame.type == pinocchio.BODY}
    worst_pose = worst_jacobian = 0.0
    for q, qd, _, _ in _states(model, seed=10 + len(robot))[:25]:
        q_pin, _ = _pinocchio_state(model, reference, q, qd)
        pinocchio.computeJointJacobians(reference, data, q_pin)
        pinocchio.framesForwardKinematics(reference, data, q_pin)
        origins = model.point_positions(q)
        for i, link in enumerate(links):
            frame = reference.getFrameId(link, pinocchio.BODY)
            rotation, origin = frame_placement(model, q, link)
            placement = data.oMf[frame]
            assert np.array_equal(origins[i], origin)
            worst_pose = max(worst_pose, np.abs(rotation - placement.rotation).max(),
                             np.abs(origin - placement.translation).max())
            jacobian = pinocchio.getFrameJacobian(reference, data, frame, pinocchio.LOCAL_WORLD_ALIGNED)[:, rows]
            worst_jacobian = max(worst_jacobian, np.abs(frame_jacobian(model, q, link) - jacobian).max())
    print(f"{robot}: worst frame errors vs Pinocchio: placement {worst_pose:.1e}, Jacobian {worst_jacobian:.1e}")
    assert worst_pose < 1e-12 and worst_jacobian < 1e-12


@needs_pinocchio
def test_gravity_is_a_parameter() -> None:
    """A tilted gravity vector: Q(q, 0, 0) vs -rnea with Pinocchio's gravity set alike; no gravity:
    no force at rest."""
    from cmbs.model.urdf import load_urdf

    path = str(ROBOTS / URDFS["panda"])
    gravity = np.array([1.5, -2.0, -9.0])
    model = load_urdf(path, gravity=gravity)
    reference = pinocchio.buildModelFromUrdf(path)
    reference.gravity.linear = gravity
    data = reference.createData()
    rows = _velocity_indices(model, reference)
    for q, _, _, _ in _states(model, seed=3)[:10]:
        q_pin, v_pin = _pinocchio_state(model, reference, q, np.zeros(model.n))
        expected = -pinocchio.rnea(reference, data, q_pin, v_pin, np.zeros(reference.nv))[rows]
        assert _relative(model.forces(q, np.zeros(model.n)), expected) < 1e-10
    weightless = load_urdf(path, gravity=(0.0, 0.0, 0.0))
    assert np.array_equal(weightless.forces(np.full(model.n, 0.3), np.zeros(model.n)), np.zeros(model.n))


@needs_pinocchio
def test_energies() -> None:
    """T = ½ q̇ᵀ M q̇ (body by body vs the CRBA's M) and -∂V/∂q = Q(q, 0, 0) (central differences)."""
    model = cmbs.load(str(ROBOTS / URDFS["panda"]))
    for q, qd, _, _ in _states(model, seed=4)[:10]:
        M = model.mass_matrix(q)
        assert abs(model.kinetic_energy(q, qd) - 0.5 * qd @ M @ qd) <= 1e-12 * (0.5 * qd @ M @ qd)
        h = 1e-6
        gradient = np.array([(model.potential_energy(q + h * e) - model.potential_energy(q - h * e)) / (2 * h)
                             for e in np.eye(model.n)])
        assert np.allclose(-gradient, model.forces(q, np.zeros(model.n)), rtol=0, atol=1e-7)


@needs_pinocchio
def test_free_swing_conserves_energy() -> None:
    """10 s of UR5 swinging freely (zero torques) with DOP853 at rtol 1e-10: T + V drifts by at most
    1e-6 of its value."""
    model = cmbs.load(str(ROBOTS / URDFS["ur5"]))
    q0 = np.array([0.3, -1.0, 1.2, -0.5, 0.8, 0.1])
    qd0 = np.array([0.5, -0.3, 0.8, 1.0, -0.6, 0.4])
    run = cmbs.simulate(model, t_end=10.0, dt=0.01, q0=q0, qd0=qd0, integrator="dop853", rtol=1e-10, atol=1e-12)
    energy = model.energy_history(run.q, run.qd)
    assert run.t[-1] == pytest.approx(10.0)
    assert np.ptp(run.q[:, 1]) > 1.0          # it does swing
    drift = np.abs(energy - energy[0]).max() / abs(energy[0])
    print(f"ur5: relative energy drift over 10 s: {drift:.1e}")
    assert drift <= 1e-6


FALLBACK = """
import sys
import numpy as np
import cmbs, cmbs.jit
from cmbs.model.robot import frame_jacobian
assert not cmbs.jit.COMPILED
model = cmbs.load(sys.argv[1])
q, qd, u = np.linspace(-2.0, 2.0, model.n), np.linspace(1.0, -1.0, model.n), np.linspace(0.0, 3.0, model.n)
terms = model.evaluate(q, qd, 0.0, u)
np.savez(sys.argv[2], M=terms.M, Q=terms.Q, J=frame_jacobian(model, q, model.point_names[-1]),
         E=np.array([model.kinetic_energy(q, qd), model.potential_energy(q)]))
"""


@needs_pinocchio
def test_interpreted_kernels_match(tmp_path: Path) -> None:
    """Without numba (CMBS_DISABLE_NUMBA=1) the same kernels give the same terms to 1e-12."""
    path = str(ROBOTS / URDFS["panda"])
    out = tmp_path / "fallback.npz"
    environment = dict(os.environ, CMBS_DISABLE_NUMBA="1")
    subprocess.run([sys.executable, "-c", FALLBACK, path, str(out)], check=True, env=environment)
    model = cmbs.load(path)
    q, qd, u = np.linspace(-2.0, 2.0, model.n), np.linspace(1.0, -1.0, model.n), np.linspace(0.0, 3.0, model.n)
    terms = model.evaluate(q, qd, 0.0, u)
    interpreted = np.load(out)
    assert np.allclose(interpreted["M"], terms.M, rtol=0, atol=1e-12)
    assert np.allclose(interpreted["Q"], terms.Q, rtol=0, atol=1e-12)
    assert np.allclose(interpreted["J"], frame_jacobian(model, q, model.point_names[-1]), rtol=0, atol=1e-12)
    assert np.allclose(interpreted["E"], [model.kinetic_energy(q, qd), model.potential_energy(q)], rtol=0,
                       atol=1e-12)


# ------------------------------------------------------------------ bad input
ARM = """<?xml version="1.0"?>
<robot name="arm">
  <link name="base"/>
  <link name="upper">
    <inertial><origin xyz="0 0 0.25" rpy="0 0 0"/><mass value="{mass}"/>
      <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.001"/></inertial>
  </link>
  <link name="tool"/>
  <joint name="shoulder" type="{type}">
    <parent link="base"/><child link="upper"/>
    <origin xyz="{xyz}" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="10" velocity="3"/><dynamics damping="0.1"/>
  </joint>
  <joint name="wrist" type="{wrist}">
    <parent link="upper"/><child link="tool"/><origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="1 0 0"/>
  </joint>
</robot>
"""


def _arm(tmp_path: Path, *, type: str = "revolute", xyz: str = "0 0 0.1", mass: str = "2.0",
         wrist: str = "fixed") -> Path:
    path = tmp_path / "arm.urdf"
    path.write_text(ARM.format(type=type, xyz=xyz, mass=mass, wrist=wrist))
    return path


def _error(path: Path | str) -> str:
    with pytest.raises(CmbsError) as caught:
        cmbs.load(str(path))
    message = str(caught.value)
    assert "\n" not in message and str(path) in message
    return message


def test_small_arm_closed_form(tmp_path: Path) -> None:
    """One rod about y, upright at q = 0: M = I_yy + m d², Q = u + m g d sin q (d = 0.25 from the
    axis; the massless tool on a fixed joint adds nothing); limits and damping kept as data."""
    model = cmbs.load(str(_arm(tmp_path)))
    assert model.coordinate_names == ("shoulder",) and model.actuator_names == ("shoulder",)
    q = np.array([0.7])
    assert model.mass_matrix(q)[0, 0] == pytest.approx(0.02 + 2.0 * 0.25**2, rel=1e-14)
    assert model.forces(q, np.array([3.0]), u=np.array([1.5]))[0] == pytest.approx(
        1.5 + 2.0 * 9.81 * 0.25 * np.sin(0.7), rel=1e-14)
    assert frame_placement(model, q, "tool")[1] == pytest.approx([0.5 * np.sin(0.7), 0.0, 0.1 + 0.5 * np.cos(0.7)])
    joint = model.equations.joints[0]
    assert (joint.lower, joint.upper, joint.effort, joint.velocity, joint.damping) == (-2.0, 2.0, 10.0, 3.0, 0.1)


TWO_LINKS = """<?xml version="1.0"?>
<robot name="two-links">
  <joint name="elbow" type="continuous">
    <parent link="upper"/><child link="lower"/><origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="0 1 0"/>
  </joint>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/><origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="50" velocity="2"/>
  </joint>
  <link name="base"/>
  <link name="upper"><inertial><origin xyz="0 0 0.25"/><mass value="2.0"/>
    <inertia ixx="0.05" ixy="0" ixz="0" iyy="0.04" iyz="0" izz="0.01"/></inertial></link>
  <link name="lower"><inertial><origin xyz="0 0 0.2"/><mass value="1.5"/>
    <inertia ixx="0.03" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.01"/></inertial></link>
</robot>
"""


def test_two_links_closed_form(tmp_path: Path) -> None:
    """A two-link arm in the x-z plane whose joints are listed elbow first: the coordinates follow
    the file (elbow, shoulder); M and the gravity forces are the textbook double pendulum's
    (links upright at q = 0, θ = shoulder, φ = elbow, a = 0.5, c1 = 0.25, c2 = 0.2)::

        M_θθ = I1 + I2 + m1 c1² + m2 (a² + c2² + 2 a c2 cos φ),  M_θφ = I2 + m2 (c2² + a c2 cos φ),
        M_φφ = I2 + m2 c2²,  Q_θ = g (m1 c1 + m2 a) sin θ + m2 g c2 sin(θ + φ),  Q_φ = m2 g c2 sin(θ + φ)."""
    path = tmp_path / "two.urdf"
    path.write_text(TWO_LINKS)
    model = cmbs.load(str(path))
    assert model.coordinate_names == ("elbow", "shoulder")
    m1, m2, I1, I2, a, c1, c2, g = 2.0, 1.5, 0.04, 0.02, 0.5, 0.25, 0.2, 9.81
    for elbow, shoulder in ((0.0, 0.0), (0.4, -1.1), (2.5, 0.7)):
        q = np.array([elbow, shoulder])
        mss = I1 + I2 + m1 * c1**2 + m2 * (a**2 + c2**2 + 2 * a * c2 * np.cos(elbow))
        mse = I2 + m2 * (c2**2 + a * c2 * np.cos(elbow))
        mee = I2 + m2 * c2**2
        assert np.allclose(model.mass_matrix(q), [[mee, mse], [mse, mss]], rtol=1e-14, atol=0)
        expected = [m2 * g * c2 * np.sin(shoulder + elbow),
                    g * (m1 * c1 + m2 * a) * np.sin(shoulder) + m2 * g * c2 * np.sin(shoulder + elbow)]
        assert np.allclose(model.forces(q, np.zeros(2)), expected, rtol=1e-13, atol=1e-14)
    assert [joint.type for joint in model.equations.joints] == ["continuous", "revolute"]


def test_floating_joint_is_refused(tmp_path: Path) -> None:
    message = _error(_arm(tmp_path, type="floating"))
    assert "joint 'shoulder'" in message and "floating" in message and "docs/spatial.md" in message


def test_planar_joint_is_refused(tmp_path: Path) -> None:
    message = _error(_arm(tmp_path, type="planar"))
    assert "joint 'shoulder'" in message and "planar" in message and "docs/spatial.md" in message


def test_missing_file(tmp_path: Path) -> None:
    assert "no such file" in _error(tmp_path / "missing.urdf")


def test_malformed_number(tmp_path: Path) -> None:
    message = _error(_arm(tmp_path, xyz="0 zero 0.1"))
    assert "joint 'shoulder'" in message and "xyz='0 zero 0.1'" in message
    message = _error(_arm(tmp_path, mass="2,5"))
    assert "link 'upper'" in message and "value='2,5'" in message


def test_unknown_joint_type(tmp_path: Path) -> None:
    message = _error(_arm(tmp_path, type="screw"))
    assert "joint 'shoulder'" in message and "unknown joint type 'screw'" in message


def test_movable_joint_without_inertial(tmp_path: Path) -> None:
    message = _error(_arm(tmp_path, wrist="revolute"))
    assert "joint 'wrist'" in message and "'tool'" in message and "inertial" in message


def test_not_xml(tmp_path: Path) -> None:
    path = tmp_path / "broken.urdf"
    path.write_text("<robot name='x'><link name='a'>")
    assert "not well-formed XML" in _error(path)


def test_command_line_error_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``cmbs describe`` of a bad URDF file: exit status 2 and one line, no traceback."""
    from cmbs.cli import main

    path = _arm(tmp_path, type="floating")
    assert main(["describe", str(path)]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("cmbs: error: ") and "joint 'shoulder'" in lines[0]
