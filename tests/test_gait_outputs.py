"""Gait outputs: OpenSim coordinates and generalized forces of the stride (cmbs.gait.opensim),
checked against the lab's own angles and moments and by virtual work, and the ``--animate`` /
``--opensim`` options of ``cmbs gait prepare|inverse|track``.

The tests with the ``prepared`` fixture need the public trial (fetched on first use; skipped
offline)."""

from __future__ import annotations

import re

import numpy as np
import pytest
from PIL import Image

import cmbs
from cmbs.cli import main
from cmbs.gait import INDEPENDENT
from cmbs.gait.inverse import compare_with_lab, inverse
from cmbs.gait.opensim import ANGLES, HIP_IN_PELVIS, ankle_neutral, generalized_forces, kinematics
from cmbs.opensim_files import read_storage
from cmbs.trajectory import Trajectory

LEG_COLUMNS = ("hip_flexion_r", "knee_angle_r", "ankle_angle_r", "hip_flexion_l", "knee_angle_l", "ankle_angle_l")


def pose(model, **angles_deg):
    """A one-instant motion of ``model``: its standing pose with the given independent angles
    changed [deg] and every point re-assembled."""
    q = model.q0.copy()
    for name, value in angles_deg.items():
        q[model.coordinate_index(name)] += np.radians(value)
    q = cmbs.assemble(model, q, fixed=list(INDEPENDENT))
    return Trajectory(np.zeros(1), q[None, :], np.zeros((1, model.n)), np.zeros((1, model.n)),
                      model.coordinate_names)


def test_standing_pose_is_opensim_zero_and_a_hand_made_pose_has_the_documented_signs():
    model = cmbs.load("human")
    standing = kinematics(model, pose(model))
    hip = [model.q0[model.coordinate_index(name)] for name in ("hip.x", "hip.z")]
    assert standing["pelvis_tx"][0] == pytest.approx(hip[0] - HIP_IN_PELVIS[0], abs=1e-12)
    assert standing["pelvis_ty"][0] == pytest.approx(hip[1] - HIP_IN_PELVIS[1], abs=1e-12)
    assert all(abs(values[0]) < 1e-9 for name, values in standing.items() if name not in ("pelvis_tx", "pelvis_ty"))
    # knee flexed 30 deg (cmbs -30), hip flexed 20, ankle dorsiflexed 10 (toe up), left arm
    # forward 15, elbow flexed 40, head back 5, trunk leaning back 8 deg
    bent = kinematics(model, pose(model, r_knee=-30, r_hip=20, r_ankle=10, l_shoulder=15, l_elbow=40, neck=5,
                                  trunk=8))
    expected = {"knee_angle_r": 30, "hip_flexion_r": 20, "ankle_angle_r": 10, "arm_flex_l": 15, "elbow_flex_l": 40,
                "neck_extension": 5, "pelvis_tilt": 8, "knee_angle_l": 0, "lumbar_extension": 0}
    for name, value in expected.items():
        assert bent[name][0] == pytest.approx(value, abs=1e-9), name
    # the thigh really is forward and the shank behind it: the OpenSim signs are the anatomical ones
    points = dict(zip(model.point_names, model.point_positions(pose(model, r_knee=-30, r_hip=20).q[0])))
    assert points["r_knee"][0] > points["hip"][0] and points["r_ankle"][0] < points["r_knee"][0]


def test_mapped_leg_angles_follow_the_labs_own_angles(prepared):
    """The lab's sagittal angles (from its own marker model, flexion/dorsiflexion > 0) against
    the exported ones: stride 1 correlations 0.991/0.998/0.94 (hip/knee/ankle, right), mean
    differences hip -4.9 deg (the lab's hip is measured from the pelvis, ours from the hip-neck
    line), knee 0.8, ankle -2.2 with the measured flat-foot neutral; 22-26 deg with the
    library's standing ankle instead."""
    model, reference = prepared.model, prepared.motion
    neutral = ankle_neutral(reference)
    ours = kinematics(model, reference, ankle=neutral)
    lab = np.degrees(reference["lab_angles"])
    for j, name in enumerate(LEG_COLUMNS):
        r = np.corrcoef(ours[name], lab[:, j])[0, 1]
        offset = np.mean(ours[name] - lab[:, j])
        assert r > (0.9 if "ankle" in name else 0.98), (name, r)
        assert abs(offset) < {"hip": 7.0, "knee": 3.0, "ankle": 4.0}[name.split("_")[0]], (name, offset)
    standing = kinematics(model, reference)
    assert all(np.mean(standing[name] - lab[:, j]) > 20.0 for j, name in enumerate(LEG_COLUMNS) if "ankle" in name)
    assert np.degrees(neutral["r_ankle"]) == pytest.approx(83.0, abs=0.1)
    assert np.degrees(neutral["l_ankle"]) == pytest.approx(88.3, abs=0.1)


def test_exported_moments_against_the_labs_moments(prepared):
    """OpenSim moments are positive in the positive coordinate direction (hip and knee flexion,
    dorsiflexion); the lab's are extensor/plantarflexor positive: OpenSim = -m x lab.  Exactly
    the cmbs lab-convention curves, and correlated with the lab's measured moments as in
    docs/gait.md (0.81/0.94/0.98 right, 0.75/0.89/0.98 left)."""
    model, reference = prepared.model, prepared.motion
    result = inverse(model, reference, "grf")
    columns = generalized_forces(model, reference, result.forces)
    mass = result.body_mass
    ours = np.stack([columns[f"{name}_moment"] for name in LEG_COLUMNS], axis=1)
    assert np.allclose(ours, -mass * compare_with_lab(result, reference).model, atol=1e-9)
    lab = np.asarray(reference["lab_moments"])
    for j, name in enumerate(LEG_COLUMNS):
        r = np.corrcoef(ours[:, j], -mass * lab[:, j])[0, 1]
        assert r > {"hip": 0.7, "knee": 0.8, "ankle": 0.95}[name.split("_")[0]], (name, r)


def test_generalized_forces_do_the_same_virtual_work(prepared):
    """Q_os . dq_os/dz_j = Q_j for each of the 14 independent coordinates z_j: the OpenSim
    columns are the same generalized force in the OpenSim coordinates (central differences of
    :func:`kinematics`, degrees turned back into radians)."""
    model, reference = prepared.model, prepared.motion
    frame = 40
    motion = Trajectory(reference.t[frame:frame + 1], reference.q[frame:frame + 1], reference.qd[frame:frame + 1],
                        reference.qdd[frame:frame + 1], reference.names)
    forces = np.random.default_rng(7).standard_normal((1, len(INDEPENDENT))) * 50.0
    columns = generalized_forces(model, motion, forces)
    step = 1e-6

    def coordinates(j, delta):
        q = motion.q.copy()
        q[0, model.coordinate_index(INDEPENDENT[j])] += delta
        mapped = kinematics(model, Trajectory(motion.t, q, motion.qd, motion.qdd, motion.names))
        return {name: value[0] if name in ("pelvis_tx", "pelvis_ty") else np.radians(value[0])
                for name, value in mapped.items()}

    for j, name in enumerate(INDEPENDENT):
        plus, minus = coordinates(j, step), coordinates(j, -step)
        work = 0.0
        for label, value in columns.items():
            coordinate = label.rsplit("_", 1)[0]
            work += value[0] * (plus[coordinate] - minus[coordinate]) / (2 * step)
        assert work == pytest.approx(forces[0, j], rel=1e-6, abs=1e-6), name
    assert {label.rsplit("_", 1)[0] for label in columns} == set(plus) - {"lumbar_extension"}


def test_cli_writes_animations_and_opensim_files(prepared, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    model, reference = prepared.model, prepared.motion
    assert main(["gait", "prepare", "--out", "ref.npz", "--animate", "ref.gif", "--opensim", "ref.mot"]) == 0
    text = capsys.readouterr().out
    assert "OpenSim kinematics -> ref.mot" in text and "animation -> ref.gif" in text
    with Image.open("ref.gif") as image:
        assert image.n_frames == 35            # 1.13 s at 30 fps
    labels, data, header = read_storage("ref.mot")
    expected = kinematics(model, reference, ankle=ankle_neutral(reference))
    assert labels == ["time", *expected] and header["inDegrees"] == "yes" and header["nRows"] == str(len(reference.t))
    assert np.array_equal(data[:, 0], reference.t)
    assert np.allclose(data[:, 1:], np.column_stack(list(expected.values())), rtol=1e-12, atol=1e-12)

    assert main(["gait", "inverse", "--opensim", "id.sto"]) == 0
    labels, data, header = read_storage("id.sto")
    forces = generalized_forces(model, reference, inverse(model, reference, "grf").forces)
    assert labels == ["time", *forces] and header["inDegrees"] == "no"
    assert np.allclose(data[:, 1:], np.column_stack(list(forces.values())), rtol=1e-12, atol=1e-9)

    assert main(["gait", "track", "--t-end", "0.1", "--animate", "run.gif", "--opensim", "run.mot"]) == 0
    with Image.open("run.gif") as image:
        assert image.n_frames == 4             # 0.1 s at 30 fps
    labels, data, _ = read_storage("run.mot")
    assert data[0, 0] == 0.0 and data[-1, 0] == pytest.approx(0.1) and labels[1:] == list(expected)
    # the run starts 5 deg above the reference on the trunk and every cmbs joint angle
    start = dict(zip(labels, data[0]))
    assert start["pelvis_tilt"] == pytest.approx(expected["pelvis_tilt"][0] + 5.0, abs=1e-6)
    for name, sign in ANGLES.values():
        assert start[name] == pytest.approx(expected[name][0] + 5.0 * sign, abs=1e-6), name
    capsys.readouterr()


@pytest.mark.parametrize("argv, message", [
    (["gait", "prepare", "--out", "ref.npz", "--opensim", "ref.txt"], r"--opensim must end in \.sto or \.mot"),
    (["gait", "inverse", "--opensim", "id.csv"], r"--opensim must end in \.sto or \.mot"),
    (["gait", "track", "--out", "run.npz", "--animate", "run.png"], r"--animate must end in \.gif or \.mp4"),
    (["gait", "prepare", "--opensim", "missing/ref.mot"], "does not exist"),
])
def test_cli_bad_paths_fail_cleanly_before_any_work(tmp_path, capsys, monkeypatch, argv, message):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("cmbs: error: ") and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1 and re.search(message, err)
    assert list(tmp_path.iterdir()) == []
