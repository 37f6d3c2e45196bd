"""Tracking runs and robustness studies (cmbs.control.study): measures against the closed-form
error of computed-torque control, fault parsing, and the study table from the CLI."""

import re

import numpy as np
import pytest

import cmbs
from cmbs.cli import main
from cmbs.control import ComputedTorque, Reference
from cmbs.control.study import Fault, format_table, robustness_study, track
from cmbs.errors import CmbsError

OMEGA = 8.0          # critically damped CTC: kp = ω², kd = 2ω


@pytest.fixture(scope="module")
def four_bar():
    driven = cmbs.load("four-bar")
    motion = cmbs.kinematic_analysis(driven, np.linspace(0.0, 1.5, 301))
    plant = driven.without_drivers()
    law = ComputedTorque(plant, Reference(motion, ["alpha"]), kp=OMEGA**2, kd=2 * OMEGA)
    return plant, law, motion


def test_measures_of_a_wrong_initial_state_follow_the_closed_form(four_bar):
    """e(t) = δ (1 + ωt) e^{-ωt}: settling to 1 % at ωt = 6.6384, NRMSE from its integral."""
    plant, law, motion = four_bar
    delta = 0.05
    result = track(plant, law, motion, ["alpha"], t_end=1.5, faults=[Fault.parse(f"initial:{delta}")],
                   rtol=1e-10, atol=1e-12)
    assert result.succeeded
    t = motion.t
    error = delta * (1 + OMEGA * t) * np.exp(-OMEGA * t)
    # the run's own error, not just its summary, follows the closed form
    np.testing.assert_allclose(result.run["alpha"] - motion["alpha"], error, atol=1e-6)
    ratio = 6.638352067 / OMEGA           # root of (1 + x) e^{-x} = 0.01
    assert abs(result.settling_time - ratio) <= t[1] - t[0]
    expected = np.sqrt(np.trapezoid(error**2, t) / t[-1]) / np.ptp(motion["alpha"])
    np.testing.assert_allclose(result.nrmse, [expected], rtol=1e-3)
    assert result.rms_norm > 0 and result.peak_norm >= result.rms_norm


def test_robustness_study_runs_each_fault_alone(four_bar):
    plant, law, motion = four_bar
    runs = robustness_study(plant, law, motion, ["alpha"], t_end=1.5,
                            faults=["mass:coupler:1.025", "offset:20", "scale:0.9"])
    labels = [run.label for run in runs]
    assert labels == ["nominal", "mass:coupler:1.025", "offset:20", "scale:0.9"]
    assert all(run.succeeded for run in runs)
    assert runs[0].nrmse[0] < 1e-6              # the exact model starting on the reference
    for run in runs[1:]:                         # each fault alone shows, none diverges
        assert 1e-5 < run.nrmse[0] < 0.05
    table = format_table(runs, "four-bar")
    assert "mass:coupler:1.025" in table and "NRMSE alpha %" in table
    with_start_error = robustness_study(plant, law, motion, ["alpha"], t_end=1.5, faults=["offset:20"],
                                        common=["initial:0.05"])
    assert [run.label for run in with_start_error] == ["nominal", "offset:20"]
    assert with_start_error[0].nrmse[0] > 1e-3 and with_start_error[1].settling_time == np.inf


def test_seeded_noise_is_reproducible_and_time_determined(four_bar):
    plant, law, motion = four_bar
    first, second = (track(plant, law, motion, ["alpha"], t_end=0.5, faults=[Fault.parse("noise:0.002:3")],
                           integrator="rk4") for _ in range(2))
    np.testing.assert_array_equal(first.run.q, second.run.q)
    other = track(plant, law, motion, ["alpha"], t_end=0.5, faults=[Fault.parse("noise:0.002:4")], integrator="rk4")
    assert np.abs(other.run.q - first.run.q).max() > 1e-6


@pytest.mark.parametrize("text", ["bogus:1", "mass:coupler", "mass:coupler:x", "offset:", "initial:1:2", "noise:nan"])
def test_fault_mistakes(text):
    with pytest.raises(CmbsError, match="expected mass:SEGMENT:FACTOR"):
        Fault.parse(text)


def test_cli_study_prints_the_table(capsys):
    status = main(["track", "four-bar", "--t-end", "1", "--dt", "0.01", "--study", "--initial-error", "0.05",
                   "--fault", "mass:coupler:1.025", "--fault", "offset:10"])
    text = capsys.readouterr().out
    assert status == 0
    assert "robustness study (all cases: initial:0.05)" in text
    assert text.count("success") == 3


ARM_REFERENCE = "theta2 = -1.2 + 0.2*sin(t); theta3 = -0.9 + 0.1*t"


def _track_nrmse(capsys, *options):
    status = main(["track", "arm-on-slider", "--reference", ARM_REFERENCE, "--t-end", "1", "--initial-error", "0.02",
                   *options])
    text = capsys.readouterr().out
    assert status == 0, text
    line = text.split("NRMSE (of the reference's range) ")[1].split(";")[0]
    return [float(value) / 100 for value in re.findall(r"(\S+) %", line)]     # printed in % of the range


def test_cli_controllers_on_the_redundantly_actuated_arm(capsys):
    """PIDC, Udwadia-Kalaba tracking and computed torque impose the same error dynamics
    ë + K_d ė + K_p e = 0 with an exact model, so they track identically; the hybrid law adds
    only a constraint force, which does not change the motion (it samples at 1 kHz)."""
    pidc = _track_nrmse(capsys, "--controller", "pidc")
    uk = _track_nrmse(capsys, "--controller", "udwadia-kalaba")
    ctc = _track_nrmse(capsys, "--controller", "ctc")
    hybrid = _track_nrmse(capsys, "--controller", "hybrid", "--force", "5", "--integrator", "rk4", "--dt", "0.001",
                          "--sample-rate", "1000")
    assert 1e-3 < pidc[0] < 0.05
    np.testing.assert_allclose(uk, pidc, rtol=1e-3)
    np.testing.assert_allclose(ctc, pidc, rtol=1e-3)
    np.testing.assert_allclose(hybrid, pidc, rtol=2e-2)     # sampled at 1 kHz instead of continuous


def test_cli_hybrid_force_mistake(capsys):
    assert main(["track", "arm-on-slider", "--reference", ARM_REFERENCE, "--t-end", "1", "--controller", "hybrid",
                 "--force", "five"]) == 2
    assert "--force 'five'" in capsys.readouterr().err
