"""Gait step 1: data and reconstruction (cmbs.gait; docs/gait.md).

The recorded trial is fetched from PyPI on first use (gaitalytics 0.2.2 sdist); tests that need
it skip with the reason when it cannot be fetched (offline).
"""

from __future__ import annotations

import io
import tarfile

import numpy as np
import pytest
from scipy.optimize import minimize

from cmbs.cli import main
from cmbs.errors import CmbsError
from cmbs.gait import GaitDataError, prepare_stride, subject_lengths
from cmbs.gait.data import NORMATIVE, TRIAL, Source, _extract, fetch, read_normative, read_trial
from cmbs.gait.reconstruct import (cycle_phase, estimate, fit_frame, joint_centres, measured_lengths,
                                   normative_angles, prepare, sagittal_frame, segment_lengths, smooth,
                                   stride_window, weights)

G = 9.81


@pytest.fixture(scope="module")
def data():
    try:
        trial = read_trial(fetch(TRIAL))
        curves = read_normative(fetch(NORMATIVE))
    except GaitDataError as error:
        pytest.skip(f"gait data not available: {error}")
    return trial, curves


@pytest.fixture(scope="module")
def prepared(data):
    return prepare_stride(1)


def test_reference_satisfies_every_rigid_body_constraint(prepared):
    model, motion = prepared.model, prepared.motion
    for q_fit, q in zip(motion["q_fit"], motion.q):
        assert np.max(np.abs(model.constraints(q_fit))) <= 1e-9
        assert np.max(np.abs(model.constraints(q))) <= 1e-9


# the segments of MEASURED_SEGMENTS (name, side column) each measured point bounds
ADJACENT = {"hip": [("trunk", 0), ("thigh", 0), ("thigh", 1)], "neck": [("trunk", 0)],
            "r_knee": [("thigh", 0), ("shank", 0)], "r_ankle": [("shank", 0), ("foot", 0)], "r_toe": [("foot", 0)],
            "l_knee": [("thigh", 1), ("shank", 1)], "l_ankle": [("shank", 1), ("foot", 1)], "l_toe": [("foot", 1)]}


def test_reference_stays_near_measured_joint_centres(prepared):
    """Bound from the data: the model's lengths are constant (the subject's medians) while the
    measured sagittal lengths vary over the frames (out-of-plane motion, skin and joint-centre
    errors: thigh 0.401-0.432 m, shank 0.420-0.453 m).  A joint centre between two segments
    whose measured lengths are both off can be off by the sum of the two mismatches; the bound
    is the largest such sum over the points and frames of the stride (38.6 mm for stride 1)."""
    model, motion, centres = prepared.model, prepared.motion, prepared.centres
    lengths = segment_lengths(model)
    measured = measured_lengths(centres)
    deviation = {point: sum(np.abs(measured[s][:, side] - lengths[s]) for s, side in segments)
                 for point, segments in ADJACENT.items()}
    bound = max(float(np.max(d)) for d in deviation.values())
    assert 0.01 < bound < 0.05          # the data's own inconsistency: 1-5 cm
    stats = prepared.statistics
    assert np.all(stats.fit_max <= bound) and np.all(stats.ref_max <= bound), (stats.ref_max, bound)
    assert np.all(stats.ref_rms <= 0.6 * bound)
    # the stored joint centres are the measured ones the statistics refer to
    assert np.allclose(motion["joint_centres"][:, 0], centres["hip"])


def test_subject_lengths_bring_the_model_closer_to_the_joint_centres(data, prepared):
    """The medians of the measured lengths replace the linearly scaled table (trunk 0.489 ->
    0.509 m, shank 0.415 -> 0.428 m): every point's RMS distance drops, the overall RMS by more
    than a quarter, and the neck (whose only measured segment, the trunk, varies by 3 mm about
    its median) comes within 5 mm instead of 2 cm."""
    trial, _ = data
    lengths = subject_lengths(trial)
    assert set(lengths) == {"trunk", "thigh", "shank", "foot"}
    model_lengths = segment_lengths(prepared.model)
    assert all(model_lengths[name] == pytest.approx(value, abs=1e-12) for name, value in lengths.items())
    scaled = prepare_stride(1, subject_specific=False).statistics
    fitted = prepared.statistics
    assert np.all(fitted.ref_rms < scaled.ref_rms), (fitted.ref_rms, scaled.ref_rms)
    assert np.sqrt(np.mean(fitted.ref_rms**2)) < 0.75 * np.sqrt(np.mean(scaled.ref_rms**2))
    assert fitted.ref_max[list(fitted.points).index("neck")] < 0.005 < scaled.ref_max[list(scaled.points).index("neck")]


def test_fit_is_the_constrained_weighted_least_squares_minimum(data, prepared):
    """Eq. 4.3 at one frame solved independently by scipy's SLSQP gives the same q; and the KKT
    condition W (q - q̂) ∈ range(Aᵀ) holds."""
    trial, curves = data
    model = prepared.model
    frame = sagittal_frame(trial)
    start, _ = stride_window(trial, 1)
    index = int(np.argmin(np.abs(trial.time - (start + 0.3))))
    centres = {p: xz[index:index + 1] for p, xz in joint_centres(trial, frame).items()}
    q_hat = estimate(model, centres, normative_angles(curves, trial.time[index:index + 1], trial))[0]
    w = weights(model)
    q, _ = fit_frame(model, q_hat, w, q_hat)
    scale = w.max()
    reference = minimize(lambda x: 0.5 * np.sum(w * (x - q_hat) ** 2) / scale, q_hat,
                         jac=lambda x: w * (x - q_hat) / scale, method="SLSQP",
                         constraints=[{"type": "eq", "fun": model.constraints, "jac": model.jacobian}],
                         options={"ftol": 1e-14, "maxiter": 500})
    assert reference.success, reference.message
    assert np.max(np.abs(q - reference.x)) < 1e-5
    gradient = w * (q - q_hat)
    A = model.jacobian(q)
    multipliers, *_ = np.linalg.lstsq(A.T, -gradient, rcond=None)
    assert np.max(np.abs(gradient + A.T @ multipliers)) <= 1e-8 * np.max(np.abs(gradient))


def test_velocities_and_accelerations_are_consistent(prepared):
    model, motion = prepared.model, prepared.motion
    for q, qd, qdd in zip(motion.q, motion.qd, motion.qdd):
        terms = model.evaluate(q, qd, 0.0)
        assert np.max(np.abs(terms.A @ qd)) <= 1e-9
        assert np.max(np.abs(terms.A @ qdd - terms.gamma)) <= 1e-8
    h = motion.t[1] - motion.t[0]
    # central differences are exact up to h²/6 |third derivative|; bound it from the data
    for position, rate, higher in ((motion.q, motion.qd, motion.qdd), (motion.qd, motion.qdd, None)):
        difference = (position[2:] - position[:-2]) / (2 * h)
        if higher is None:
            third = np.abs(np.diff(motion.qdd, 2, axis=0)) / h**2
        else:
            third = np.abs(np.diff(higher, axis=0)) / h
        allowed = 2 * h**2 / 6 * third.max(axis=0) + 1e-9
        assert np.all(np.abs(difference - rate[1:-1]) <= allowed)


def test_stride_duration_matches_the_events(data, prepared):
    trial, _ = data
    strikes = trial.strikes("Right")
    motion = prepared.motion
    assert motion.t[0] == 0.0
    assert motion.t[-1] == pytest.approx(strikes[1] - strikes[0], abs=1e-6)
    assert len(motion.t) == round((strikes[1] - strikes[0]) * trial.rate) + 1
    events = {(side, label, round(time, 3)) for side, label, time in motion.info["events"]}
    assert ("Right", "Foot Strike", 0.0) in events and ("Right", "Foot Strike", round(motion.t[-1], 3)) in events


def test_ground_reaction_forces_carry_body_weight_and_match_the_events(data, prepared):
    """Over a whole stride of steady treadmill walking the mean vertical GRF is the body weight;
    the right plate is loaded from heel strike to the right foot-off event."""
    trial, _ = data
    motion = prepared.motion
    vertical = motion["r_grf"][:-1, 1] + motion["l_grf"][:-1, 1]
    assert np.mean(vertical) == pytest.approx(trial.body_mass * G, rel=0.03)
    foot_off = next(t for side, label, t in motion.info["events"] if side == "Right" and label == "Foot Off")
    contact, t = motion["r_contact"], motion.t
    assert np.all(contact[(t > 0.02) & (t < foot_off - 0.02)])
    assert not np.any(contact[(t > foot_off + 0.02) & (t < t[-1] - 0.02)])
    loaded = contact.nonzero()[0]
    heel = motion.q[loaded[0], motion.names.index("r_ankle.x")]
    assert abs(motion["r_cop"][loaded[0], 0] - heel) < 0.1    # CoP under the heel at heel strike


def test_smoothing_spline_is_a_low_pass_filter_with_the_stated_cutoff():
    t = np.arange(0.0, 3.0, 0.01)
    for frequency in (2.0, 6.0, 15.0):
        gain = np.abs(smooth(t, np.sin(2 * np.pi * frequency * t), 6.0, t)[0][100:200]).max()
        assert gain == pytest.approx(1.0 / (1.0 + (frequency / 6.0) ** 4), abs=0.01)


def test_cycle_phase():
    strikes = np.array([1.0, 2.0, 3.5])
    phase = cycle_phase(np.array([1.0, 1.5, 2.75, 3.5 - 1e-9, 4.25, 0.5]), strikes)
    assert np.allclose(phase, [0.0, 0.5, 0.5, 1.0, 0.5, 0.5], atol=1e-6)


def test_bad_stride_and_missing_file_give_clear_errors(data, tmp_path):
    trial, curves = data
    with pytest.raises(CmbsError, match="no such C3D file"):
        read_trial(tmp_path / "missing.c3d")
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(b"not a c3d file")
    with pytest.raises(CmbsError, match="not a readable C3D"):
        read_trial(bad)
    with pytest.raises(CmbsError, match="no such normative"):
        read_normative(tmp_path / "missing.json")
    for stride in (0, 11, 1.5, True):
        with pytest.raises(CmbsError, match="stride must be an integer from 1 to 10"):
            stride_window(trial, stride)
    with pytest.raises(CmbsError, match="cutoff"):
        prepare(trial, curves, prepare_model(trial), 1, cutoff=80.0)


def prepare_model(trial):
    from cmbs.library import load_library_model

    return load_library_model("human", body_mass=trial.body_mass, height=trial.height)


def test_fetch_uses_the_cache_and_reports_a_missing_member(tmp_path):
    source = Source("example", "1.0", "data/file.txt", "MIT")
    cached = tmp_path / "example-1.0" / "file.txt"
    cached.parent.mkdir()
    cached.write_text("cached")
    assert fetch(source, tmp_path) == cached           # no download when cached
    archive = tmp_path / "example-1.0.tar.gz"
    with tarfile.open(archive, "w:gz") as tar:
        payload = b"hello"
        info = tarfile.TarInfo("example-1.0/data/other.txt")
        info.size = len(payload)
        tar.addfile(info, io.BytesIO(payload))
    with pytest.raises(GaitDataError, match="has no member 'data/file.txt'"):
        _extract(archive, source, tmp_path / "out.txt")


def test_cli_prepare(data, tmp_path, capsys):
    out = tmp_path / "reference.npz"
    assert main(["gait", "prepare", "--stride", "2", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "right stride 2" in text and "max constraint residual" in text and out.is_file()
    assert main(["gait", "prepare", "--stride", "99", "--out", str(out)]) == 2
    assert "stride must be an integer from 1 to 10" in capsys.readouterr().err
    assert main(["gait", "prepare", "--out", str(tmp_path / "reference.txt")]) == 2


def test_human_lengths_keep_mass_com_and_gyration_fractions():
    """human(lengths=...): the shank's mass, COM fraction and radius-of-gyration fraction stay, the
    standing heights stack the new lengths; unknown segments and bad values are ModelErrors."""
    from cmbs.errors import ModelError
    from cmbs.library import load_library_model
    from cmbs.model.model import base_equations

    def shank(model):
        segment = next(s for s in base_equations(model)[0].segments if s.name == "r_shank")
        return segment.mass, segment.com[0] / segment.length, segment.inertia / (segment.mass * segment.length**2)

    scaled = load_library_model("human", body_mass=55.33, height=1.7197)
    longer = load_library_model("human", body_mass=55.33, height=1.7197, lengths={"shank": 0.45})
    assert np.allclose(shank(scaled), shank(longer), rtol=1e-12)
    assert segment_lengths(longer)["shank"] == pytest.approx(0.45)
    heights = [dict(zip(m.point_names, m.point_positions(m.q0)[:, 1]))["head"] for m in (scaled, longer)]
    assert heights[1] - heights[0] == pytest.approx(0.45 - segment_lengths(scaled)["shank"], abs=1e-12)
    assert longer.total_mass == pytest.approx(scaled.total_mass, rel=1e-12)
    with pytest.raises(ModelError, match="unknown segment 'tibia'"):
        load_library_model("human", lengths={"tibia": 0.4})
    with pytest.raises(ModelError, match="must be a positive number"):
        load_library_model("human", lengths={"shank": -0.4})
