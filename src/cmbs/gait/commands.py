"""The ``cmbs gait`` commands: ``prepare`` (data → reference motion), ``inverse`` (joint torques
of a stride against the lab's moments) and ``track`` (open-loop replay, PD or computed-torque
tracking with faults), with stick-figure animations and OpenSim ``.mot``/``.sto`` export of their
results; see docs/gait.md."""

from __future__ import annotations

import argparse

import numpy as np

import cmbs
from cmbs.cli import Offset, _check_output, _UsageError


def add_gait_commands(commands) -> None:
    """Register ``gait prepare|inverse|track`` on the top-level subparsers ``commands``."""
    gait = commands.add_parser("gait", help="human gait on the public treadmill recording (docs/gait.md)",
                               description="Human gait on the public treadmill recording (docs/gait.md).")
    gait_commands = gait.add_subparsers(dest="gait_command", required=True, metavar="STEP")
    prepare = gait_commands.add_parser("prepare", help="data -> kinematically consistent reference motion",
                                       description="Fetch the trial, fit the human model to one right stride, "
                                                   "smooth and differentiate, save the reference motion.")
    prepare.add_argument("--stride", type=int, default=1, help="right stride, 1 = first heel strike to the second")
    prepare.add_argument("--cutoff", type=float, default=6.0, help="smoothing-spline cut-off frequency [Hz]")
    prepare.add_argument("--out", default="reference.npz", help="reference motion file (.npz or .csv)")
    prepare.add_argument("--plot", help="figure of the independent coordinates (.png, .pdf or .svg)")
    prepare.add_argument("--animate", help="stick-figure animation of the reconstructed walker (.gif, .mp4 or .html "
                                           "viewer)")
    prepare.add_argument("--opensim", help="reference kinematics in OpenSim coordinates (.mot or .sto)")
    prepare.set_defaults(run=_gait_prepare)
    inverse = gait_commands.add_parser("inverse", help="inverse dynamics of a stride, compared with the lab's moments",
                                       description="Joint torques of one right stride with (a) the contact "
                                                   "wrench at the hip and (b) the measured ground reaction "
                                                   "forces at the centres of pressure; hip residuals; "
                                                   "correlation with the lab's leg moments.")
    inverse.add_argument("--stride", type=int, default=1, help="right stride, 1 = first heel strike to the second")
    inverse.add_argument("--cutoff", type=float, default=6.0, help="smoothing-spline cut-off frequency [Hz]")
    inverse.add_argument("--out", help="result file (.npz or .csv): reference plus torques and residuals")
    inverse.add_argument("--plot", help="figure of the leg torques vs the lab's moments (.png, .pdf or .svg)")
    inverse.add_argument("--opensim", help="generalized forces of (b) as OpenSim inverse-dynamics output (.sto or "
                                           ".mot)")
    inverse.set_defaults(run=_gait_inverse)
    follow = gait_commands.add_parser("track",
                                      help="forward dynamics: open-loop replay, PD or computed-torque tracking",
                                      description="Forward dynamics of one right stride on the human model with "
                                                  "residual actuators: the IDA forces replayed open loop, or PD / "
                                                  "computed-torque tracking of the recorded motion with robustness "
                                                  "faults (docs/gait.md).")
    follow.add_argument("--controller", choices=("pd", "ctc", "open"), default="ctc",
                        help="pd, ctc (computed torque) or open (open-loop replay of the IDA forces)")
    follow.add_argument("--contact", choices=("grf", "hip"), default="grf",
                        help="grf: measured GRF as known loads; hip: the residual actuators carry the contact")
    follow.add_argument("--fault", action="append", default=[],
                        help="extra case, repeatable: mass:SEGMENT:FACTOR[:T0], offset:VALUE[:T0], "
                             "scale:FACTOR[:T0], noise:SIGMA[:SEED], initial:DELTA")
    follow.add_argument("--stride", type=int, default=1, help="right stride, 1 = first heel strike to the second")
    follow.add_argument("--cutoff", type=float, default=6.0, help="smoothing-spline cut-off frequency [Hz]")
    follow.add_argument("--initial-error", type=Offset.parse, default="5deg", metavar="VALUE[deg]",
                        help="initial error on the trunk and the 11 joint angles, in rad or in degrees as 5deg "
                             "(0: the recorded state)")
    follow.add_argument("--omega", type=float, default=20.0, help="closed-loop natural frequency [rad/s]")
    follow.add_argument("--no-feed-forward", action="store_true", help="PD without the IDA feed-forward")
    follow.add_argument("--t-end", type=float, help="simulated time [s] (default: the stride)")
    follow.add_argument("--dt", type=float, default=1e-3, help="RK4 step [s]")
    follow.add_argument("--out", help="nominal run (.npz or .csv)")
    follow.add_argument("--plot", help="figure of the tracking errors (.png, .pdf or .svg)")
    follow.add_argument("--animate", help="stick-figure animation of the nominal run over the reference (.gif, "
                                          ".mp4 or .html viewer)")
    follow.add_argument("--opensim", help="nominal run in OpenSim coordinates (.mot or .sto)")
    follow.set_defaults(run=_gait_track)


def _prepared_stride(args: argparse.Namespace):
    """The stride of ``--stride``/``--cutoff``, after checking the output paths ``--out``,
    ``--plot``, ``--animate`` and ``--opensim`` the command has (so that a bad path fails before
    any work)."""
    from cmbs.gait import prepare_stride
    from cmbs.opensim_files import SUFFIXES

    for option, suffixes in (("out", (".npz", ".csv")), ("plot", (".png", ".pdf", ".svg")),
                             ("opensim", SUFFIXES)):
        if getattr(args, option, None):
            _check_output(getattr(args, option), suffixes, f"--{option}")
    if getattr(args, "animate", None):
        from cmbs.animate import checked_animation_path

        checked_animation_path(args.animate, "--animate")     # an .mp4 also needs ffmpeg
    return prepare_stride(args.stride, cutoff=args.cutoff)


def _gait_prepare(args: argparse.Namespace) -> int:
    from cmbs.gait import INDEPENDENT

    prepared = _prepared_stride(args)
    motion, stats, info = prepared.motion, prepared.statistics, prepared.motion.info
    print(f"gait: {info['trial']}, right stride {args.stride}: {len(motion.t)} frames at {info['frame_rate']:g} Hz, "
          f"stride time {info['stride_time']:.3f} s (heel strike at t = {info['trial_time_of_t0']:.2f} s)")
    print(f"  model human ({info['model_parameters']['body_mass']:.1f} kg, {info['model_parameters']['height']:.3f} m);"
          f" forward axis {info['forward_axis']}; {info['smoothing']}")
    print(f"  max constraint residual: fit {stats.fit_constraint:.2g}, reference {stats.ref_constraint:.2g} "
          f"({stats.iterations} SQP iterations at most)")
    print(f"  {'point':<9}{'fit RMS mm':>11}{'fit max mm':>11}{'ref RMS mm':>11}{'ref max mm':>11}")
    for j, point in enumerate(stats.points):
        print(f"  {point:<9}{1e3 * stats.fit_rms[j]:>11.1f}{1e3 * stats.fit_max[j]:>11.1f}"
              f"{1e3 * stats.ref_rms[j]:>11.1f}{1e3 * stats.ref_max[j]:>11.1f}")
    print(f"  force plates: right foot on plate {info['plates']['r']}, left foot on plate {info['plates']['l']}")
    print(f"  reference -> {motion.save(args.out)}")
    if args.plot:
        from cmbs.plotting import plot_trajectory, save_figure

        figure = plot_trajectory(motion, model=prepared.model, coordinates=INDEPENDENT[2:])
        print(f"  figure -> {save_figure(figure, args.plot)}")
    if args.opensim:
        from cmbs.gait.opensim import ankle_neutral, write_kinematics

        path = write_kinematics(args.opensim, prepared.model, motion, ankle=ankle_neutral(motion))
        print(f"  OpenSim kinematics -> {path}")
    if args.animate:
        from cmbs.animate import animate

        print(f"  animation -> {animate(prepared.model, motion, args.animate)}")
    return 0


def _gait_inverse(args: argparse.Namespace) -> int:
    import time

    from cmbs.gait.inverse import JOINTS, compare_with_lab, inverse, residual_summary

    prepared = _prepared_stride(args)
    model, reference = prepared.model, prepared.motion
    height = model.parameters["height"]
    print(f"gait inverse dynamics: right stride {args.stride}, {len(reference.t)} frames, model human "
          f"({model.total_mass:.2f} kg, {height:.3f} m, subject-specific trunk/leg lengths)")
    results, comparisons, extras = {}, {}, {}
    for mode, label in (("hip", "(a) contact wrench at the hip"), ("grf", "(b) measured GRF at the CoPs")):
        started = time.perf_counter()
        result = results[mode] = inverse(model, reference, mode)
        elapsed = time.perf_counter() - started
        summary = residual_summary(result, height)
        comparison = comparisons[mode] = compare_with_lab(result, reference)
        print(f"  {label}: {1e3 * elapsed:.1f} ms")
        print(f"    hip residual     {'RMS':>8}{'peak':>9}{'RMS %':>8}{'peak %':>8}")
        for j, (name, unit) in enumerate((("force x", "N"), ("force z", "N"), ("torque", "N m"))):
            print(f"    {name:<8} [{unit:>3}]{summary.rms[j]:>8.1f}{summary.peak[j]:>9.1f}"
                  f"{summary.rms_percent[j]:>8.2f}{summary.peak_percent[j]:>8.2f}")
        print("    (% of body weight m g for forces, of m g x height for the torque)")
        print(f"    vs lab moments   correlation  (lab low-passed {comparison.cutoff:g} Hz)  RMS diff [N m/kg]")
        for joint, r, filtered, rms in zip(comparison.joints, comparison.correlation,
                                           comparison.correlation_filtered, comparison.rms_difference):
            print(f"    {joint:<16}{r:>12.3f}{filtered:>26.3f}{rms:>19.3f}")
        extras[f"torques_{mode}"] = result.torques
        extras[f"residual_{mode}"] = result.residual
        extras[f"lab_convention_{mode}"] = comparison.model
    peaks = np.max(np.abs(results["grf"].torques), axis=0)
    print("  peak |joint torque| (b) [N m]: " + ", ".join(f"{j} {v:.1f}" for j, v in zip(JOINTS, peaks)))
    if args.out:
        info = {**reference.info, "analysis": "gait inverse dynamics (cmbs gait inverse)", "joints": list(JOINTS),
                "residual": ["hip force x [N]", "hip force z [N]", "torque about the hip [N m]"],
                "lab_convention": "leg torques in the lab's sign convention [N m/kg], order of lab_moments"}
        saved = cmbs.Trajectory(reference.t, reference.q, reference.qd, reference.qdd, reference.names,
                                {**reference.extras, **extras}, info)
        print(f"  result -> {saved.save(args.out)}")
    if args.plot:
        from cmbs.gait.plots import plot_lab_comparison
        from cmbs.plotting import save_figure

        figure = plot_lab_comparison(reference, comparisons)
        print(f"  figure -> {save_figure(figure, args.plot)}")
    if args.opensim:
        from cmbs.gait.opensim import write_moments

        path = write_moments(args.opensim, model, reference, results["grf"].forces)
        print(f"  OpenSim generalized forces of (b) -> {path}")
    return 0


#: the largest initial error on the joint angles (rad) ``cmbs gait track`` takes
LARGEST_JOINT_OFFSET = 0.5


def _joint_offset_degrees(offset: Offset) -> float:
    """``--initial-error`` in degrees (its library unit); a plain number is in rad and must not
    exceed LARGEST_JOINT_OFFSET (29°: every joint that far off is no start for tracking a
    stride), which also catches a number meant as degrees."""
    radians = offset.in_unit_of("rad", "--initial-error", "joint angles")
    if abs(radians) > LARGEST_JOINT_OFFSET:
        raise _UsageError(f"--initial-error {offset.text()}: {radians:.3g} rad on every joint angle is more than "
                          f"{LARGEST_JOINT_OFFSET:g} rad ({np.degrees(LARGEST_JOINT_OFFSET):.0f} deg); for degrees "
                          f"write the unit, e.g. 5deg")
    return float(np.degrees(radians))


def _gait_track(args: argparse.Namespace) -> int:
    from cmbs.control.study import format_table
    from cmbs.gait import INDEPENDENT
    from cmbs.gait.track import open_loop, tracking_study

    degrees = _joint_offset_degrees(args.initial_error)     # checked before any work
    prepared = _prepared_stride(args)
    model, reference = prepared.model, prepared.motion
    contact = {"grf": "measured GRF at the CoPs, residual actuators at the hip",
               "hip": "no ground: the hip/trunk actuators carry the contact wrench"}[args.contact]
    print(f"gait tracking: right stride {args.stride} ({reference.t[-1]:.3f} s), human model with residual "
          f"actuators, contact {args.contact} ({contact}); RK4, h = {args.dt:g} s")
    if args.controller == "open":
        result = open_loop(model, reference, args.contact, t_end=args.t_end, step=args.dt)
        run, runs = result.run, {"open loop": result.run}
        peak = np.abs(result.error).max(axis=0)
        print(f"  open loop (IDA forces, spline inputs): status {run.info['status']} at t = {run.t[-1]:.3f} s")
        if np.isfinite(result.departed):
            print(f"  |error| exceeds 5 deg / 5 cm at t = {result.departed:.3f} s ({result.coordinate})")
        else:
            print("  |error| stays within 5 deg / 5 cm")
        print("  peak |error|: " + ", ".join(f"{name} {1e3 * v:.1f} mm" if name.startswith("hip.") else
                                             f"{name} {np.degrees(v):.2f} deg" for name, v in zip(INDEPENDENT, peak)))
        succeeded = True
    else:
        runs_list = tracking_study(model, reference, args.controller, contact=args.contact, faults=args.fault,
                                   initial_error=degrees, t_end=args.t_end, omega=args.omega,
                                   feed_forward=not args.no_feed_forward, step=args.dt)
        gains = (f"K_p = {args.omega ** 2:g} s^-2, K_d = {2 * args.omega:g} s^-1" if args.controller == "ctc" else
                 f"K_p = omega^2 m_z + m g l_leg, K_d = 2 sqrt(K_p m_z), omega = {args.omega:g} rad/s"
                 + ("" if args.no_feed_forward else ", IDA feed-forward"))
        print(format_table(runs_list, f"  {args.controller.upper()} ({gains}), initial error "
                                      f"{degrees:g} deg on the trunk and joint angles"))
        print("  (hip NRMSE over the hip's range of motion; inputs: N m on angles, N on hip.x, hip.z)")
        run, runs = runs_list[0].run, {r.label: r.run for r in runs_list}
        succeeded = all(r.succeeded for r in runs_list)
    if args.out:
        print(f"  result -> {run.save(args.out)}")
    if args.plot:
        from cmbs.gait.plots import plot_tracking
        from cmbs.plotting import save_figure

        print(f"  figure -> {save_figure(plot_tracking(runs, reference, INDEPENDENT), args.plot)}")
    if args.opensim:
        from cmbs.gait.opensim import ankle_neutral, write_kinematics

        path = write_kinematics(args.opensim, model, run, ankle=ankle_neutral(reference))
        print(f"  OpenSim kinematics -> {path}")
    if args.animate:
        from cmbs.animate import animate

        print(f"  animation -> {animate(model, run, args.animate, reference=reference)}")
    return 0 if succeeded else 1
