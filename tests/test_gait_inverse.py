"""Gait step 2: inverse dynamics of the recorded stride (cmbs.gait.inverse; docs/gait.md).

Needs the public trial (fetched on first use); skips with the reason when offline.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import BPoly

from cmbs.cli import main
from cmbs.errors import CmbsError
from cmbs.gait.inverse import (INDEPENDENT, QuinticHermite, centre_of_mass, compare_with_lab, cop_local, inverse,
                               prescribed_model, replay)
from cmbs.inverse.ida import inverse_dynamics
from cmbs.model.natural import point_map
from cmbs.trajectory import Trajectory

G = 9.81


@pytest.fixture(scope="module")
def results(prepared):
    return {mode: inverse(prepared.model, prepared.motion, mode) for mode in ("hip", "grf")}


def test_quintic_hermite_matches_scipy():
    t = np.array([0.0, 0.1, 0.25, 0.3])
    z, v, a = np.sin(3 * t), 3 * np.cos(3 * t), -9 * np.sin(3 * t)
    f = QuinticHermite(t, z, v, a)
    reference = BPoly.from_derivatives(t, np.stack([z, v, a], axis=1))
    for s in np.linspace(0.0, 0.3, 37):
        assert np.allclose(f(s), [reference(s), reference(s, 1), reference(s, 2)], atol=1e-9)


def test_cop_local_coordinates_and_generalized_force():
    """A horizontal foot (ankle (0, 0.1), toe (0.2, 0.1)) with the CoP at (0.05, 0): ξ = 0.25,
    η = -0.5 (0.1 m below = half a foot length, clockwise side); the generalized force [I-C, C]ᵀF
    does the virtual work F·δp of the point for any δq (δp from finite differences)."""
    ankle, toe, cop = np.array([[0.0, 0.1]]), np.array([[0.2, 0.1]]), np.array([[0.05, 0.0]])
    assert np.allclose(cop_local(ankle, toe, cop), [[0.25, -0.5]])
    rng = np.random.default_rng(1)
    x = rng.normal(size=4)
    xi, eta = cop_local(x[None, :2], x[None, 2:], np.array([[0.3, -0.2]]))[0]

    def point(y: np.ndarray) -> np.ndarray:
        d = y[2:] - y[:2]
        return y[:2] + xi * d + eta * np.array([-d[1], d[0]])

    assert np.allclose(point(x), [0.3, -0.2])
    force, dq = np.array([12.0, 500.0]), rng.normal(size=4)
    generalized = point_map(1.0, (xi, eta)).T @ force
    work = force @ (point(x + 1e-6 * dq) - point(x - 1e-6 * dq)) / 2e-6
    assert generalized @ dq == pytest.approx(work, rel=1e-8)


@pytest.mark.parametrize("mode", ["hip", "grf"])
def test_velocity_transformation_matches_lagrange_multipliers(prepared, results, mode):
    """Q_z = Rᵀ(M q̈ - Q) equals minus the multipliers of the prescribed model's driver rows
    (cmbs.inverse_dynamics, method lagrange: another formula, the full augmented system)."""
    result = results[mode]
    reference = prepared.motion
    driven = prescribed_model(prepared.model, reference, result.loads)
    motion = Trajectory(reference.t, reference.q, reference.qd, reference.qdd, reference.names)
    lagrange = inverse_dynamics(driven, motion, method="lagrange")
    order = [lagrange.driven_coordinates.index(name) for name in INDEPENDENT]
    scale = np.max(np.abs(result.forces))
    assert np.max(np.abs(lagrange.forces[:, order] - result.forces)) <= 1e-9 * scale


@pytest.mark.parametrize("mode", ["hip", "grf"])
def test_hip_wrench_closes_the_external_force_balance(prepared, results, mode):
    """Σ m a_G = hip force + GRF + m g, a_G from central second differences of the whole-body
    COM of the reference poses (no q̈ used).  The difference's error is h²/12 |x''''| (x'''' from
    the fourth differences): the bound is twice that, plus 1 N."""
    result, reference, model = results[mode], prepared.motion, prepared.model
    mass, h = model.total_mass, reference.t[1] - reference.t[0]
    com = centre_of_mass(model, reference.q)
    accel = (com[2:] - 2 * com[1:-1] + com[:-2]) / h**2
    external = result.residual[1:-1, :2] + mass * np.array([0.0, -G])
    if mode == "grf":
        external = external + reference["r_grf"][1:-1] + reference["l_grf"][1:-1]
    fourth = np.abs(np.diff(com, 4, axis=0)).max(axis=0) / h**4
    allowed = 2 * mass * h**2 / 12 * fourth + 1.0
    assert np.all(np.abs(mass * accel - external) <= allowed), (np.abs(mass * accel - external).max(axis=0), allowed)


def test_measured_grf_makes_the_hip_wrench_a_small_residual(prepared, results):
    """Mode hip carries the body weight at the hip (vertical RMS ≈ m g); with the GRF at the CoPs
    the residual force is a few % of body weight (measured RMS 4.6 % and 4.1 %, torque 0.65 % of
    m g h for stride 1); bounds: RMS below 6 % m g and 1.5 % m g h, 20× smaller vertically."""
    weight, height = prepared.model.total_mass * G, prepared.model.parameters["height"]
    hip = np.sqrt(np.mean(results["hip"].residual ** 2, axis=0))
    grf = np.sqrt(np.mean(results["grf"].residual ** 2, axis=0))
    assert hip[1] == pytest.approx(weight, rel=0.05)
    assert grf[0] < 0.06 * weight and grf[1] < 0.06 * weight and grf[2] < 0.015 * weight * height
    assert grf[1] < hip[1] / 20


def test_leg_torques_correlate_with_the_lab_moments(prepared, results):
    """Measured (stride 1, GRF mode) correlations r_hip, r_knee, r_ankle, l_hip, l_knee, l_ankle:
    0.81, 0.94, 0.98, 0.75, 0.89, 0.98 (strides 5 and 9: hip 0.78-0.87, knee 0.84-0.91, ankle
    ≥ 0.975).  The lab's hip moment carries unfiltered high-frequency content at heel strike;
    against it low-passed at 6 Hz the hips reach 0.95 and 0.97.  Thresholds: ankle 0.95, knee
    0.8, hip 0.7 raw and 0.9 filtered; RMS difference below 0.3 N m/kg.  Without the GRF (hip
    mode) the stance leg is computed as if in the air: the ankles do not correlate (|r| < 0.3)."""
    grf = compare_with_lab(results["grf"], prepared.motion)
    threshold = {"hip": 0.7, "knee": 0.8, "ankle": 0.95}
    for joint, r, rms, filtered in zip(grf.joints, grf.correlation, grf.rms_difference, grf.correlation_filtered):
        assert r > threshold[joint[2:]], (joint, r)
        assert rms < 0.3, (joint, rms)
        if joint.endswith("hip"):
            assert filtered > 0.9, (joint, filtered)
    hip = compare_with_lab(results["hip"], prepared.motion)
    assert np.all(np.abs(hip.correlation[[2, 5]]) < 0.3)
    # the sign mapping matters: the opposite sign gives negative correlations
    assert np.all(np.corrcoef(-grf.model.T, grf.lab.T).diagonal(6) < -0.7)


@pytest.mark.parametrize("mode, start", [("hip", 0.0), ("grf", 0.4)])
def test_replayed_torques_reproduce_the_motion(prepared, mode, start):
    """The IDA torques (1 ms steps, linear between) and the same external loads, forward
    dynamics over 0.1 s from the prescribed state: hip within 0.01 mm, angles within 0.2° (measured
    5e-5 mm / 2e-4° in hip mode, 8e-4 mm / 0.08° in GRF mode at mid-stance; the error is the
    O(h²) input interpolation, see the next test)."""
    run, prescribed = replay(prepared.model, prepared.motion, mode, start, 0.1)
    columns = prepared.model.coordinate_indices(list(INDEPENDENT))
    assert np.allclose(run.t, prescribed.t)
    error = np.abs(run.q[:, columns] - prescribed.q[:, columns])
    assert error[:, :2].max() < 1e-5 and error[:, 2:].max() < np.radians(0.2), error.max(axis=0)


def test_replay_error_is_the_second_order_input_interpolation(prepared):
    """At heel strike (double support, both feet loaded; the light feet under the GRF are the most
    sensitive) the replay error falls by ≈ 4 when the IDA step halves: 1.43° → 0.36° (left ankle)."""
    columns = prepared.model.coordinate_indices(list(INDEPENDENT))
    errors = []
    for step in (1e-3, 5e-4):
        run, prescribed = replay(prepared.model, prepared.motion, "grf", 0.0, 0.1, step=step)
        errors.append(np.abs(run.q[:, columns] - prescribed.q[:, columns]).max())
    assert 3.0 < errors[0] / errors[1] < 5.0, errors
    assert errors[1] < np.radians(0.5)


def test_bad_mode_and_times(prepared):
    with pytest.raises(CmbsError, match="mode must be one of hip, grf"):
        inverse(prepared.model, prepared.motion, "foot")
    with pytest.raises(CmbsError, match="times must lie in the stride"):
        inverse(prepared.model, prepared.motion, "grf", times=np.array([0.0, 5.0]))


def test_cli_gait_inverse(prepared, tmp_path, capsys):
    out = tmp_path / "inverse.npz"
    assert main(["gait", "inverse", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "residual" in text and "correlation" in text and "r_knee" in text and out.is_file()
    saved = Trajectory.load(out)
    assert saved.extras["torques_grf"].shape == (len(prepared.motion.t), 11)
    assert main(["gait", "inverse", "--stride", "99"]) == 2
    assert "stride must be an integer from 1 to 10" in capsys.readouterr().err
