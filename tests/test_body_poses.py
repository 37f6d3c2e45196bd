"""Poses of spatial bodies (cmbs.kinematics.body_poses) and their columns in result files: the
rotation maps body-fixed points and vectors onto the model's own positions, is orthonormal with
det +1, its quaternion (scalar first, written out here) is the same rotation, and two closed
forms: a torque-free top spinning about its symmetry axis, and Bricard's first rod turning
about its ground axis y."""

from __future__ import annotations

import math

import numpy as np
import pytest

import cmbs
from cmbs.cli import main
from cmbs.errors import CmbsError, ModelError
from cmbs.kinematics import body_poses, with_body_poses


def matrix_of(quaternion: np.ndarray) -> np.ndarray:
    """The rotation matrix of a unit quaternion (w, x, y, z), written out."""
    w, x, y, z = quaternion
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def element(model: cmbs.Model, q: np.ndarray, name: str) -> np.ndarray:
    """The position of point or unit vector ``name`` at q, from its coordinates."""
    return np.array([q[..., model.coordinate_index(f"{name}.{axis}")] for axis in "xyz"]).T


def check_rotations(poses) -> None:
    """Each R orthonormal with det +1, each quaternion a unit one of the same rotation."""
    rotations = poses.rotations.reshape(-1, 3, 3)
    quaternions = poses.quaternions.reshape(-1, 4)
    assert np.allclose(rotations @ np.swapaxes(rotations, 1, 2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(rotations), 1.0, atol=1e-12)
    assert np.allclose(np.linalg.norm(quaternions, axis=1), 1.0, atol=1e-12)
    for quaternion, rotation in zip(quaternions, rotations):
        assert np.allclose(matrix_of(quaternion), rotation, atol=1e-12)


@pytest.fixture(scope="module")
def top_run():
    model = cmbs.load("heavy-top")
    return model, cmbs.simulate(model, t_end=0.5, dt=0.01, rtol=1e-10, atol=1e-12)


def test_the_top_rotation_maps_its_tip_and_axes(top_run):
    model, run = top_run
    assert run.info["status"] == "success"
    poses = body_poses(model, run.q)
    assert poses.names == ("top",)
    assert poses.origins.shape == (run.t.size, 1, 3) and poses.quaternions.shape == (run.t.size, 1, 4)
    check_rotations(poses)
    R, origin = poses.rotations[:, 0], poses.origins[:, 0]
    assert np.allclose(origin, 0.0)                                   # the fixed tip O
    start = dict(zip(model.point_names, model.point_positions(model.q0)))
    tip = element(model, run.q, "tip")
    assert np.abs(tip[-1] - start["tip"]).max() > 0.05                # it has moved
    mapped = origin + np.einsum("kij,j->ki", R, start["tip"] - start["O"])
    assert run["constraint_error"].max() < 1e-8
    assert np.abs(mapped - tip).max() < 1e-8                          # to the constraint error
    for axis in "uvw":
        assert np.abs(np.einsum("kij,j->ki", R, element(model, model.q0, axis)) - element(model, run.q, axis)).max() \
            < 1e-8
    sign = np.einsum("ki,ki->k", poses.quaternions[1:, 0], poses.quaternions[:-1, 0])
    assert np.all(sign > 0)                                           # no jumps between q and -q
    assert poses.quaternions[0, 0, 0] == pytest.approx(1.0)           # the start as built: no rotation


def test_a_torque_free_top_spinning_about_its_axis_turns_at_its_rate():
    """Without gravity, a symmetric top set spinning at ω about its symmetry axis w (tilted 20°
    from z) keeps turning about w at ω: q(t) = (cos ωt/2, sin ωt/2 w)."""
    omega, tilt = 10.0, math.radians(20.0)
    model = cmbs.load("heavy-top", gravity=0.0, spin=omega)
    run = cmbs.simulate(model, t_end=0.5, dt=0.05, rtol=1e-10, atol=1e-12)
    assert run.info["status"] == "success"
    w = np.array([0.0, -math.sin(tilt), math.cos(tilt)])
    half = 0.5 * omega * run.t
    expected = np.column_stack([np.cos(half), np.sin(half)[:, None] * w])
    quaternions = body_poses(model, run.q).quaternions[:, 0]
    assert half[-1] > 2.0                                             # more than 4 rad turned
    assert np.abs(quaternions - expected).max() < 1e-7


@pytest.fixture(scope="module")
def bricard_configurations():
    """Bricard's mechanism as built and with its first rod turned 0.2 and 0.4 rad about y
    (assembled with P1 held there)."""
    model = cmbs.load("bricard")
    rows = [np.array(model.q0)]
    for angle in (0.2, 0.4):
        q = np.array(model.q0)
        q[model.coordinate_index("P1.x")], q[model.coordinate_index("P1.z")] = math.cos(angle), -math.sin(angle)
        rows.append(cmbs.assemble(model, q, fixed=["P1.x", "P1.z"]))
    return model, np.array(rows), np.array([0.0, 0.2, 0.4])


def test_bricard_rods_turn_their_joint_points_and_axes(bricard_configurations):
    model, q, _ = bricard_configurations
    assert np.abs(model.constraints(q[-1])).max() < 1e-10
    poses = body_poses(model, q)
    assert poses.names == tuple(f"rod{k}" for k in range(5))
    check_rotations(poses)

    def position(name: str) -> np.ndarray:
        """(configurations, 3) of a point or vector, fixed ones included."""
        if f"{name}.x" in model.coordinate_names:
            return element(model, q, name)
        start = {**dict(zip(model.point_names, model.point_positions(model.q0))),
                 "a0": np.array([0.0, 1.0, 0.0]), "a5": np.array([1.0, 0.0, 0.0])}
        return np.broadcast_to(start[name], (len(q), 3))

    for k in range(5):
        R, origin = poses.rotations[:, k], poses.origins[:, k]
        assert np.allclose(origin, position(f"P{k}"), atol=1e-12)
        turned = origin + np.einsum("cij,j->ci", R, position(f"P{k + 1}")[0] - position(f"P{k}")[0])
        assert np.allclose(turned, position(f"P{k + 1}"), atol=1e-9)
        for axis in (f"a{k}", f"a{k + 1}"):
            assert np.allclose(np.einsum("cij,j->ci", R, position(axis)[0]), position(axis), atol=1e-9)
    # a revolute joint: the relative rotation of two neighbours turns about their common axis
    for k in range(4):
        relative = np.swapaxes(poses.rotations[:, k], 1, 2) @ poses.rotations[:, k + 1]
        axis = position(f"a{k + 1}")[0]
        assert np.allclose(relative @ axis, axis, atol=1e-9)
    assert np.abs(poses.rotations[-1] - np.eye(3)).max() > 0.1      # the rods have turned


def test_bricard_first_rod_turns_about_the_ground_axis_y(bricard_configurations):
    """Rod 0 turns about the fixed axis y through P0: q = (cos θ/2, 0, sin θ/2, 0) with θ the
    angle P1 has turned, atan2(-z, x)."""
    model, q, angles = bricard_configurations
    P1 = element(model, q, "P1")
    theta = np.arctan2(-P1[:, 2], P1[:, 0])
    assert np.allclose(theta, angles, atol=1e-12)
    expected = np.column_stack([np.cos(theta / 2), np.zeros_like(theta), np.sin(theta / 2), np.zeros_like(theta)])
    assert np.allclose(body_poses(model, q).quaternions[:, 0], expected, atol=1e-12)


def test_one_configuration_and_non_finite_rows(bricard_configurations):
    model, q, _ = bricard_configurations
    single = body_poses(model, q[1])
    assert single.rotations.shape == (5, 3, 3) and single.quaternions.shape == (5, 4)
    assert np.allclose(single.rotations, body_poses(model, q).rotations[1])
    broken = q.copy()
    broken[1, 0] = np.nan
    poses = body_poses(model, broken)
    assert np.all(np.isnan(poses.quaternions[1])) and np.all(np.isfinite(poses.quaternions[[0, 2]]))


def test_body_poses_of_a_model_without_spatial_bodies():
    with pytest.raises(ModelError, match="neither a spatial model"):
        body_poses(cmbs.load("four-bar"), cmbs.load("four-bar").q0)
    model = cmbs.load("bricard")
    with pytest.raises(ModelError, match=r"shape \(24,\) or \(k, 24\)"):
        body_poses(model, np.zeros(5))
    pendulum = cmbs.load("spherical-pendulum")               # a rod, no body
    assert body_poses(pendulum, pendulum.q0).names == ()
    run = cmbs.Trajectory(np.zeros(1), pendulum.q0[None], np.zeros((1, 3)), np.zeros((1, 3)),
                          pendulum.coordinate_names)
    assert with_body_poses(pendulum, run) is run


def test_result_files_hold_the_poses(top_run, tmp_path):
    model, run = top_run
    poses = body_poses(model, run.q)
    for suffix in (".csv", ".npz"):
        written = cmbs.Trajectory.load(with_body_poses(model, run).save(tmp_path / f"top{suffix}"))
        for k, axis in enumerate("xyz"):
            assert np.allclose(written[f"top.origin.{axis}"], poses.origins[:, 0, k], rtol=0, atol=1e-15)
        for k, part in enumerate(("qw", "qx", "qy", "qz")):
            assert np.allclose(written[f"top.{part}"], poses.quaternions[:, 0, k], rtol=0, atol=1e-15)
        assert np.array_equal(written.q, run.q)
    header = (tmp_path / "top.csv").read_text().splitlines()[1].split(",")
    assert header[-7:] == ["top.origin.x", "top.origin.y", "top.origin.z", "top.qw", "top.qx", "top.qy", "top.qz"]


def test_a_pose_column_may_not_take_a_coordinate_name():
    b = cmbs.SpatialModelBuilder("clash")
    b.add_point("O", (0.0, 0.0, 0.0), fixed=True)
    b.add_point("box.origin", (0.0, 0.0, 1.0))
    for name, direction in (("u", (1, 0, 0)), ("v", (0, 1, 0)), ("w", (0, 0, 1))):
        b.add_vector(name, direction)
    b.add_body("box", origin="O", basis=["u", "v", "w"], mass=1.0, com=(0, 0, 0), inertia=np.eye(3),
               points=["box.origin"])
    model = b.build()
    run = cmbs.Trajectory(np.zeros(1), model.q0[None], np.zeros((1, model.n)), np.zeros((1, model.n)),
                          model.coordinate_names)
    with pytest.raises(CmbsError, match="'box.origin.x', which is already a coordinate"):
        with_body_poses(model, run)


def test_cli_writes_poses_and_a_viewer(tmp_path, capsys):
    out, page = tmp_path / "top.csv", tmp_path / "top.html"
    assert main(["simulate", "heavy-top", "--t-end", "0.2", "--out", str(out), "--animate", str(page)]) == 0
    printed = capsys.readouterr().out
    assert f"result -> {out}" in printed and f"animation -> {page}" in printed
    written = cmbs.Trajectory.load(out)
    model = cmbs.load("heavy-top")
    assert np.allclose(np.column_stack([written[f"top.{part}"] for part in ("qw", "qx", "qy", "qz")]),
                       body_poses(model, written.q).quaternions[:, 0], atol=1e-15)
    assert page.read_text().startswith("<!DOCTYPE html>")
