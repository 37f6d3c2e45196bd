"""cmbs.sweep: batched, process-pool and Dask runs give the numbers of single simulations."""

import re

import numpy as np
import pytest

import cmbs
from cmbs.errors import CmbsError
from cmbs.simulate import simulate
from cmbs.sweep import SweepResult, Variant, grid, sweep


@pytest.fixture(scope="module")
def four_bar():
    return cmbs.load("four-bar").without_drivers()


def _initial_states(model, count):
    """Consistent start states: the crank released at several speeds."""
    variants = []
    for k, speed in enumerate(np.linspace(-1.0, 1.0, count)):
        qd = cmbs.velocities(model, model.q0, qd=np.eye(model.n)[-1] * speed + 1e-3 * k)
        variants.append(Variant(qd0=qd, label=f"speed {speed:+.2f}"))
    return variants


def test_batched_sweep_equals_single_simulations(four_bar):
    variants = _initial_states(four_bar, 5)
    result = sweep(four_bar, variants, t_end=0.5, dt=1e-3, every=10, formulation="baumgarte")
    assert result.info["mode"] == "batched" and len(result) == 5
    assert result.t.shape == (51,) and result.q.shape == (5, 51, four_bar.n)
    for v, variant in enumerate(variants):
        run = simulate(four_bar, t_end=0.5, dt=1e-3, integrator="rk4", formulation="baumgarte",
                       qd0=np.asarray(variant.qd0))
        np.testing.assert_allclose(result.q[v], run.q[::10], rtol=0, atol=1e-12)
        np.testing.assert_allclose(result.qd[v], run.qd[::10], rtol=0, atol=1e-11)
        np.testing.assert_allclose(result.energy[v], run["energy"][::10], rtol=0, atol=1e-9)
        np.testing.assert_allclose(result.constraint_error[v], run["constraint_error"][::10], rtol=1e-6, atol=1e-12)
    assert set(result.status) == {"success"}


def test_process_pool_equals_serial_and_the_batched_path(four_bar):
    variants = _initial_states(four_bar, 4)
    batched = sweep(four_bar, variants, t_end=0.3, dt=1e-3, every=5)
    serial = sweep(four_bar, variants, t_end=0.3, dt=1e-3, every=5, batched=False, workers=1)
    pooled = sweep(four_bar, variants, t_end=0.3, dt=1e-3, every=5, batched=False, workers=2)
    assert (serial.info["mode"], pooled.info["mode"]) == ("processes", "processes")
    np.testing.assert_array_equal(pooled.q, serial.q)
    np.testing.assert_allclose(batched.q, serial.q, rtol=0, atol=1e-12)


@pytest.mark.parametrize("path", ["batched", "serial", "processes"])
def test_progress_bar_counts_every_variant_and_changes_no_result(four_bar, capsys, monkeypatch, path):
    """With ``progress`` the bar on stderr reaches N/N; the batched path then runs in blocks of
    variants (here blocks of 8 of 20), which must give the one-call batch's numbers exactly."""
    import importlib

    monkeypatch.setattr(importlib.import_module("cmbs.sweep"), "PROGRESS_BLOCKS", 3)
    variants = _initial_states(four_bar, 20 if path == "batched" else 3)
    options = {"batched": {}, "serial": {"batched": False, "workers": 1},
               "processes": {"batched": False, "workers": 2}}[path]
    quiet = sweep(four_bar, variants, t_end=0.1, dt=1e-3, every=10, **options)
    capsys.readouterr()
    shown = sweep(four_bar, variants, t_end=0.1, dt=1e-3, every=10, progress=True, **options)
    bar = capsys.readouterr().err
    assert f"{len(variants)}/{len(variants)}" in bar and "sweep four-bar" in bar
    assert shown.info["mode"] == ("batched" if path == "batched" else "processes")
    np.testing.assert_array_equal(shown.q, quiet.q)
    np.testing.assert_array_equal(shown.status, quiet.status)


def test_parameter_grid_and_mass_faults_run_through_simulate():
    """The slider-crank's crank speed and gravity on a grid; a heavier crank changes the motion
    exactly as mass_fault + simulate does."""
    variants = grid(crank_speed=[1.0, 2.0], gravity=[0.0, 9.81])
    result = sweep("slider-crank", variants, t_end=0.2, dt=1e-3, every=20, formulation="matrix-r", workers=1)
    assert result.info["mode"] == "processes" and len(result) == 4
    for v, variant in enumerate(variants):
        run = simulate(cmbs.load("slider-crank", **variant.parameters), t_end=0.2, dt=1e-3, integrator="rk4",
                       formulation="matrix-r")
        np.testing.assert_allclose(result.q[v], run.q[::20], rtol=0, atol=1e-12)
    # energy of a conservative variant is conserved; twice the crank speed turns it about 0.2 rad
    # further in 0.2 s (variants 0 and 2: 1 and 2 rad/s without gravity)
    assert np.abs(result.energy[0] - result.energy[0, 0]).max() < 1e-8
    assert 0.15 < result.coordinate("theta1")[2, -1] - result.coordinate("theta1")[0, -1] < 0.25
    heavier = sweep("slider-crank", [Variant(), Variant(masses={"crank": 1.5})], t_end=0.2, dt=1e-3,
                    formulation="matrix-r", workers=1)
    from cmbs.control import mass_fault
    expected = simulate(mass_fault(cmbs.load("slider-crank"), "crank", factor=1.5), t_end=0.2, dt=1e-3,
                        integrator="rk4", formulation="matrix-r")
    np.testing.assert_allclose(heavier.q[1], expected.q, rtol=0, atol=1e-12)
    # the heavier mechanism's own energy is conserved (the nominal-mass energy is not)
    assert np.abs(heavier.energy[1] - heavier.energy[1, 0]).max() < 1e-8
    assert np.abs(expected["energy"] - expected["energy"][0]).max() > 1e-3


def test_failed_variants_are_marked_and_the_file_round_trips(tmp_path):
    """Plain Lagrange stops at the slider-crank's singular position (t ≈ 0.83 s): that variant is
    'failed' with its message, NaN after its last output; the others run on."""
    model = cmbs.load("slider-crank", gravity=9.81)
    variants = [Variant(label="at rest", qd0=np.zeros(model.n)), Variant(label="turning")]
    result = sweep(model, variants, t_end=1.0, dt=1e-3, every=10)
    assert list(result.status) == ["success", "failed"]
    assert "rank" in result.message[1] or "singular" in result.message[1]
    assert result.recorded[1] < result.t.size and np.isnan(result.q[1, result.recorded[1]:]).all()
    assert np.isfinite(result.q[1, :result.recorded[1]]).all()
    path = result.save(tmp_path / "sweep.npz")
    loaded = SweepResult.load(path)
    np.testing.assert_array_equal(loaded.q, result.q)
    assert list(loaded.status) == list(result.status) and loaded.variants[0]["label"] == "at rest"
    assert loaded.info["mode"] == "batched" and loaded.names == result.names


def _failure_time(message):
    """The time a failed run's message names (``... at t=0.834 ...``)."""
    return float(re.search(r"at t=([-+0-9.e]+)", message).group(1))


@pytest.mark.parametrize("integrator", ["rk45", "rk23", "dop853"])
def test_batched_adaptive_sweep_equals_each_variants_simulate(integrator):
    """rk45, rk23 and dop853 sweeps run batched (the adaptive loop of cmbs.simulate for each
    variant, in parallel): each variant's outputs, status and energy drift are those of its own
    cmbs.simulate run (the process path), to the last bit.  Lagrange refusing σ_min/σ_max < 0.01
    stops the slider-crank released at twice its speed before its singular position (t ≈ 0.24 s):
    that variant fails at the time simulate names, with the outputs of the steps before only;
    the others run to the end."""
    model = cmbs.load("slider-crank", gravity=9.81)
    variants = [Variant(label="at rest", qd0=np.zeros(model.n)), Variant(label="turning"),
                Variant(label="faster", qd0=2.0 * model.qd0)]
    options = dict(t_end=0.5, dt=1e-3, every=10, integrator=integrator, rtol=1e-8, atol=1e-10,
                   formulation_options={"singular_tolerance": 0.01})
    batched = sweep(model, variants, **options)
    single = sweep(model, variants, batched=False, workers=1, **options)
    assert batched.info["mode"] == "batched" and single.info["mode"] == "processes"
    assert list(batched.status) == list(single.status) == ["success", "success", "failed"]
    np.testing.assert_array_equal(batched.recorded, single.recorded)
    assert batched.recorded[1] == batched.t.size and 0 < batched.recorded[2] < batched.t.size
    for name in ("q", "qd", "energy", "constraint_error", "energy_drift"):
        np.testing.assert_array_equal(getattr(batched, name), getattr(single, name), err_msg=name)
    assert "singular" in batched.message[2]
    stop = _failure_time(batched.message[2])
    assert stop == _failure_time(single.message[2]) and 0.2 < stop < 0.3
    assert batched.t[batched.recorded[2] - 1] <= stop and np.isnan(batched.q[2, batched.recorded[2]:]).all()


def test_sweep_refuses_bad_variants(four_bar):
    with pytest.raises(CmbsError, match="q0 must have 5 values"):
        sweep(four_bar, [Variant(q0=[0.0, 1.0])], t_end=0.1)
    with pytest.raises(CmbsError, match="by library name"):
        sweep(four_bar, [Variant(parameters={"gravity": 1.0})], t_end=0.1)
    with pytest.raises(CmbsError, match="no variants"):
        sweep(four_bar, [], t_end=0.1)
    with pytest.raises(CmbsError, match="batched path needs"):
        sweep(four_bar, [Variant()], t_end=0.1, project=True, batched=True)
    with pytest.raises(CmbsError, match="no parameter"):
        sweep("slider-crank", [Variant(parameters={"colour": 1})], t_end=0.1)


# ---------------------------------------------------------------------------------- Dask
distributed = pytest.importorskip("distributed", reason="dask's distributed package is not installed")


def _start(arguments, log):
    import subprocess
    import sys

    return subprocess.Popen([sys.executable, "-m", *arguments], stdout=log, stderr=subprocess.STDOUT)


@pytest.fixture
def cluster(tmp_path):
    """A Dask scheduler and two single-threaded worker processes (no nanny, so a killed worker
    stays dead) on 127.0.0.1, started and stopped by the test."""
    import json
    import time

    scheduler_file = tmp_path / "scheduler.json"
    log = open(tmp_path / "cluster.log", "w")
    processes = [_start(["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
                         "--no-dashboard", "--scheduler-file", str(scheduler_file)], log)]
    try:
        deadline = time.monotonic() + 60
        address = None
        while address is None and time.monotonic() < deadline:
            try:                       # the scheduler creates the file, then writes it
                address = json.loads(scheduler_file.read_text())["address"]
            except (FileNotFoundError, json.JSONDecodeError, KeyError):
                time.sleep(0.1)
        assert address is not None, f"the Dask scheduler wrote no address in 60 s ({tmp_path / 'cluster.log'})"
        workers = [_start(["distributed.cli.dask_worker", address, "--nthreads", "1", "--no-nanny",
                           "--no-dashboard", "--host", "127.0.0.1"], log) for _ in range(2)]
        processes += workers
        with distributed.Client(address, timeout=30) as client:
            client.wait_for_workers(2, timeout=60)
        yield address, workers
    finally:
        for process in reversed(processes):
            process.kill()
            process.wait()
        log.close()


def test_dask_sweep_equals_the_serial_run_and_survives_a_killed_worker(cluster, capsys):
    """Eight runs with drift projection (Python loop, a fraction of a second each) on two
    workers; one worker is killed once tasks are running: its tasks run again on the other, nothing is lost, and
    every variant equals the serial run; the progress bar counts all eight."""
    import os
    import threading
    import time

    address, workers = cluster
    model = cmbs.load("four-bar").without_drivers()
    variants = _initial_states(model, 8)
    options = dict(t_end=0.4, dt=1e-3, every=20, project=True)
    serial = sweep(model, variants, workers=1, **options)
    done = {}
    capsys.readouterr()
    thread = threading.Thread(target=lambda: done.setdefault("result", sweep(model, variants, scheduler=address,
                                                                             progress=True, **options)))
    thread.start()
    with distributed.Client(address, timeout=30) as client:
        pids = client.run(os.getpid)        # worker address -> process id
        deadline = time.monotonic() + 60
        busy = []
        while not busy and time.monotonic() < deadline:
            busy = [worker for worker, tasks in client.processing().items() if tasks]
            time.sleep(0.02)
        assert busy, "no task started on the cluster"
        victim = next(process for process in workers if process.pid == pids[busy[0]])
        victim.kill()                       # the worker dies with its task(s) in hand
        victim.wait()
        thread.join(timeout=300)
        assert len(client.scheduler_info()["workers"]) == 1
    assert not thread.is_alive()
    result = done["result"]
    assert result.info["mode"] == "dask" and list(result.status) == ["success"] * 8
    np.testing.assert_array_equal(result.q, serial.q)
    np.testing.assert_array_equal(result.energy, serial.energy)
    assert "8/8" in capsys.readouterr().err


def test_dask_sweep_whose_last_worker_dies_stops_with_a_message(cluster):
    """Both workers are killed while they hold tasks: with no worker left the scheduler would
    keep the tasks forever; after worker_timeout the variants not done fail with the reason,
    those done keep their results."""
    import threading
    import time

    address, workers = cluster
    model = cmbs.load("four-bar").without_drivers()
    variants = _initial_states(model, 8)
    done = {}
    thread = threading.Thread(target=lambda: done.setdefault("result", sweep(
        model, variants, scheduler=address, worker_timeout=1.0, t_end=0.4, dt=1e-3, every=20, project=True)))
    thread.start()
    with distributed.Client(address, timeout=30) as client:
        deadline = time.monotonic() + 60
        while not any(client.processing().values()) and time.monotonic() < deadline:
            time.sleep(0.02)
    for worker in workers:
        worker.kill()
        worker.wait()
    killed = time.monotonic()
    thread.join(timeout=60)
    assert not thread.is_alive(), "the sweep waits for a worker that will never come"
    assert time.monotonic() - killed < 30
    result = done["result"]
    failed = result.status == "failed"
    assert failed.any()
    assert all("no Dask worker for 1 s" in message for message in result.message[failed])
    assert np.all(result.recorded[failed] == 0) and np.all(result.recorded[~failed] == len(result.t))


def test_a_task_that_killed_its_workers_is_a_failed_variant():
    """Dask gives up a task that took down every worker that ran it (KilledWorker): that variant
    fails with the reason, as a variant whose run fails, instead of a traceback for the sweep."""
    from types import SimpleNamespace

    from cmbs.sweep import _task_output

    class Lost:
        def result(self):
            worker = SimpleNamespace(address="tcp://127.0.0.1:4000")     # what the scheduler's record shows
            raise distributed.KilledWorker("run_variant-1", worker, allowed_failures=3)

    output = _task_output(Lost(), 4)
    assert output["status"] == "failed" and output["q"].shape == (0, 4)
    assert output["message"].startswith("its task was lost with every Dask worker that ran it")


def test_dask_sweep_names_an_unreachable_scheduler(four_bar):
    with pytest.raises(CmbsError, match="cannot reach the Dask scheduler"):
        sweep(four_bar, [Variant()], t_end=0.01, batched=False, scheduler="tcp://127.0.0.1:9")


# ---------------------------------------------------------------------------------- command line
def test_sweep_command_runs_the_grid_and_writes_result_and_figure(tmp_path, capsys):
    from cmbs.cli import main

    out, figure = tmp_path / "sweep.npz", tmp_path / "sweep.png"
    assert main(["sweep", "slider-crank", "--vary", "crank_speed=1,2", "--mass", "crank=1,1.2", "--t-end", "0.2",
                 "--dt", "1e-3", "--integrator", "rk4", "--formulation", "matrix-r", "--every", "10",
                 "--workers", "1", "--out", str(out), "--plot", str(figure), "--coordinate", "theta1"]) == 0
    printed = capsys.readouterr().out
    assert "4 variants, processes" in printed and "crank_speed=2, mass(crank)×1.2" in printed
    result = SweepResult.load(out)
    assert result.q.shape == (4, 21, 6) and figure.stat().st_size > 0
    expected = simulate(cmbs.load("slider-crank", crank_speed=2), t_end=0.2, dt=1e-3, integrator="rk4",
                        formulation="matrix-r")
    np.testing.assert_allclose(result.q[2], expected.q[::10], rtol=0, atol=1e-12)


@pytest.mark.parametrize("integrator", ["generalized-alpha", "trapezoidal"])
def test_implicit_integrators_sweep_as_single_simulations(integrator, tmp_path, capsys):
    """An implicit integrator brings its own formulation: a sweep gives none (it used to give
    lagrange, which simulate refuses with them, so every variant failed), from Python and from
    the command line, and each variant equals its single simulation."""
    variants = grid(crank_speed=[1.0, 2.0])
    result = sweep("slider-crank", variants, t_end=0.2, dt=1e-3, every=20, integrator=integrator, workers=1)
    assert list(result.status) == ["success", "success"], result.message
    for v, variant in enumerate(variants):
        run = simulate(cmbs.load("slider-crank", **variant.parameters), t_end=0.2, dt=1e-3, integrator=integrator)
        np.testing.assert_allclose(result.q[v], run.q[::20], rtol=0, atol=1e-12)
    from cmbs.cli import main

    out = tmp_path / "sweep.npz"
    assert main(["sweep", "slider-crank", "--vary", "crank_speed=1,2", "--t-end", "0.2", "--dt", "1e-3",
                 "--integrator", integrator, "--every", "20", "--workers", "1", "--out", str(out)]) == 0
    np.testing.assert_allclose(SweepResult.load(out).q, result.q, rtol=0, atol=1e-12)


def test_sweep_command_initial_speeds_are_consistent_and_batched(tmp_path, capsys):
    from cmbs.cli import main

    out = tmp_path / "speeds.npz"
    assert main(["sweep", "four-bar", "--undriven", "--speed", "alpha=0,0.5,1", "--t-end", "0.1", "--dt", "1e-3",
                 "--integrator", "rk4", "--out", str(out)]) == 0
    result = SweepResult.load(out)
    assert result.info["mode"] == "batched"
    model = cmbs.load("four-bar").without_drivers()
    column = model.coordinate_names.index("alpha")
    np.testing.assert_allclose(result.qd[:, 0, column], [0.0, 0.5, 1.0], atol=1e-12)
    for v in range(3):                       # consistent: A q̇ = 0 at the start
        A = model.jacobian(result.q[v, 0], 0.0)
        assert np.abs(A @ result.qd[v, 0]).max() < 1e-12
        # the undriven model ran (not the driven one of the library name)
        run = simulate(model, t_end=0.1, dt=1e-3, integrator="rk4", qd0=result.qd[v, 0])
        np.testing.assert_allclose(result.q[v], run.q, rtol=0, atol=1e-12)
    assert result.constraint_error.max() < 1e-9


def test_sweep_command_progress_flag(capsys):
    """``--progress`` draws the bar on stderr (off by default when stderr is not a terminal)."""
    from cmbs.cli import main

    arguments = ["sweep", "four-bar", "--undriven", "--speed", "alpha=0,1", "--t-end", "0.05", "--dt", "1e-3",
                 "--integrator", "rk4"]
    assert main(arguments) == 0
    assert "2/2" not in capsys.readouterr().err
    assert main([*arguments, "--progress"]) == 0
    assert "2/2" in capsys.readouterr().err


def test_sweep_command_mistakes_exit_2_with_one_line(tmp_path, capsys):
    from cmbs.cli import main

    cases = [(["--vary", "crank_speed"], "--vary expects NAME=V1,V2"),
             (["--vary", "colour=1,2"], "no parameter"),
             (["--speed", "nope=1,2"], "has no coordinate 'nope'"),
             (["--undriven", "--vary", "crank_speed=1,2"], "--undriven cannot be combined with --vary"),
             (["--mass", "crank=a,b"], "expected numbers"),
             ([], "needs at least one of"),
             (["--vary", "crank_speed=1,2", "--out", str(tmp_path / "x.csv")], "must end in .npz")]
    for extra, message in cases:
        assert main(["sweep", "slider-crank", "--t-end", "0.1", *extra]) == 2
        error = capsys.readouterr().err
        assert message in error and error.count("\n") == 1, (extra, error)
    assert not (tmp_path / "x.csv").exists()
