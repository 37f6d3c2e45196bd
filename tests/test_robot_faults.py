"""Mass faults on robots (cmbs.control.faults.mass_fault on a URDF tree): the faulty terms against
the heavier robot read from an edited URDF, the energy of a faulty free swing with the added
inertia's energies, and a payload fault disturbing computed-torque tracking through `cmbs track`."""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from pathlib import Path

import numpy as np
import pytest

import cmbs
from cmbs.cli import main
from cmbs.control.faults import mass_fault, mass_fault_energy_parts
from cmbs.errors import CmbsError
from test_robot_control import JOINTS, REFERENCES, UR5, closed_form_error, robot_file

pytestmark = pytest.mark.skipif(UR5 is None, reason="needs example-robot-data (the UR5 URDF)")


def _heavier_urdf(folder: Path, link: str, factor: float) -> Path:
    """The UR5 URDF with ``link``'s mass and inertia times ``factor`` (mesh paths made absolute)."""
    tree = ElementTree.parse(UR5)
    for element in tree.getroot().iter("link"):
        if element.get("name") == link:
            mass = element.find("inertial/mass")
            mass.set("value", repr(float(mass.get("value")) * factor))
            inertia = element.find("inertial/inertia")
            for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"):
                inertia.set(key, repr(float(inertia.get(key)) * factor))
    path = folder / "heavier.urdf"
    tree.write(path)
    return path


def test_a_robot_mass_fault_equals_the_heavier_robot_after_t0(tmp_path):
    """The forearm 1.3 times heavier from t0 = 1 s: before t0 the terms are the nominal robot's,
    after it those of the UR5 whose URDF says 1.3 times the forearm's mass and inertia, at 10
    random states to 1e-12 relative."""
    nominal = cmbs.load(str(UR5))
    faulty = mass_fault(nominal, "forearm_link", factor=1.3, t0=1.0)
    heavier = cmbs.load(str(_heavier_urdf(tmp_path, "forearm_link", 1.3)))
    rng = np.random.default_rng(8)
    for _ in range(10):
        q, qd, u = rng.uniform(-2, 2, 6), rng.normal(size=6), rng.normal(size=6)
        before, expected_before = faulty.evaluate(q, qd, 0.5, u), nominal.evaluate(q, qd, 0.5, u)
        after, expected_after = faulty.evaluate(q, qd, 1.5, u), heavier.evaluate(q, qd, 1.5, u)
        for got, expected in ((before, expected_before), (after, expected_after)):
            scale_M, scale_Q = np.abs(expected.M).max(), np.abs(expected.Q).max()
            np.testing.assert_allclose(got.M, expected.M, rtol=0, atol=1e-12 * scale_M)
            np.testing.assert_allclose(got.Q, expected.Q, rtol=0, atol=1e-12 * scale_Q)
        kinetic, potential = mass_fault_energy_parts(faulty, q[None], qd[None])
        np.testing.assert_allclose(nominal.kinetic_energy(q, qd) + kinetic[0], heavier.kinetic_energy(q, qd),
                                   rtol=1e-12)
        np.testing.assert_allclose(nominal.potential_energy(q) + potential[0], heavier.potential_energy(q),
                                   rtol=1e-12, atol=1e-12)


def test_robot_mass_fault_mistakes_name_the_bodies():
    nominal = cmbs.load(str(UR5))
    with pytest.raises(CmbsError, match=r"no body 'forarm_link' \(did you mean 'forearm_link'\?\); bodies .*"
                                        r"shoulder_link, upper_arm_link, forearm_link"):
        mass_fault(nominal, "forarm_link", factor=1.1)
    with pytest.raises(CmbsError, match="no body 'tool0'"):      # a link fixed to a body carries none of its own
        mass_fault(nominal, "tool0", factor=1.1)
    with pytest.raises(CmbsError, match="must be > 0"):
        mass_fault(nominal, "forearm_link", factor=0.0)


def test_a_faulty_free_swing_keeps_the_faulty_energy():
    """The wrist 3 times heavier from the start, released from a bent pose without torques, 1 s
    with DOP853 (rtol 1e-10): the nominal energy plus the added inertia's keeps its value to
    1e-7 of the energy scale, while the nominal energy alone changes by far more."""
    nominal = cmbs.load(str(UR5))
    faulty = mass_fault(nominal, "wrist_1_link", factor=3.0)
    run = cmbs.simulate(faulty, t_end=1.0, dt=0.05, q0=np.array([0.2, -1.0, 1.2, -0.4, 0.6, 0.1]),
                        integrator="dop853", rtol=1e-10, atol=1e-12)
    assert run.info["status"] == "success"
    kinetic, potential = mass_fault_energy_parts(faulty, run.q, run.qd)
    energy = nominal.energy_history(run.q, run.qd) + kinetic + potential
    scale = np.abs(potential).max() + np.abs(kinetic).max()
    assert np.abs(energy - energy[0]).max() < 1e-7 * scale
    assert np.abs(nominal.energy_history(run.q, run.qd) - energy[0]).max() > 1e-3 * scale


def test_a_payload_fault_disturbs_computed_torque_tracking(tmp_path):
    """`cmbs track --fault mass:wrist_3_link:5:0.5`: until t0 = 0.5 s the errors follow the
    nominal closed form (the controller's model is exact), after it they leave it."""
    moving = robot_file(tmp_path / "ur5-tracking.toml", {joint: r[0] for joint, r in REFERENCES.items()})
    out = tmp_path / "faulty.npz"
    assert main(["track", str(moving), "--controller", "ctc", "--initial-error", "0.1", "--t-end", "1.0",
                 "--fault", "mass:wrist_3_link:5:0.5", "--out", str(out)]) == 0
    run = cmbs.Trajectory.load(out)
    deviation = np.zeros(run.t.size)
    for k, (joint, (_, reference, rate)) in enumerate(REFERENCES.items()):
        expected = closed_form_error(run.t, 10.0, 0.1 if k == 0 else 0.0, -rate)
        deviation = np.maximum(deviation, np.abs(run[joint] - reference(run.t) - expected))
    assert deviation[run.t <= 0.5].max() < 1e-6
    assert deviation[run.t >= 0.8].max() > 1e-4
    assert JOINTS == tuple(cmbs.load(moving).coordinate_names)
