"""A pickled model (what a process-pool or Dask sweep sends to its workers) keeps its read-only
arrays read-only: its compiled kernel has the same types as the original's, so a worker runs
the loops compiled (and cached) for the original instead of compiling them again, and the terms
take M as constant where the original does."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import cmbs
from cmbs.jit import COMPILED
from cmbs.model.compiled import model_kernel
from cmbs.model.read_only import make_read_only, read_only_paths
from helpers import example_robots


def _copy(model):
    return pickle.loads(pickle.dumps(model))


def _read_only_flags(kernel) -> list[bool]:
    """Whether each array of a kernel tuple (nested tuples flattened) is read-only."""
    flags = []
    for item in kernel:
        if isinstance(item, tuple):
            flags += _read_only_flags(item)
        elif isinstance(item, np.ndarray):
            flags.append(not item.flags.writeable)
    return flags


@pytest.mark.parametrize("name", ["four-bar", "slider-crank-joint", "two-link-arm-joint", "bricard", "human",
                                  "spherical-pendulum"])
def test_a_pickled_library_model_keeps_its_read_only_arrays(name):
    model = cmbs.load(name)
    copy = _copy(model)
    kernel, copied = model_kernel(model), model_kernel(copy)
    assert any(_read_only_flags(kernel))                 # the model has constant data to keep
    assert _read_only_flags(copied) == _read_only_flags(kernel)
    assert copy.new_terms().M.flags.writeable == model.new_terms().M.flags.writeable
    for label in ("q0", "qd0", "drivers"):
        assert not getattr(copy, label).flags.writeable
    if COMPILED:
        import numba

        assert numba.typeof(copied) == numba.typeof(kernel)


def test_a_pickled_robot_keeps_its_read_only_arrays():
    robots = example_robots()
    if robots is None:
        pytest.skip("example-robot-data is not installed (the [test] extra)")
    model = cmbs.load(str(robots / "ur_description/urdf/ur5_robot.urdf"))
    kernel, copied = model_kernel(model), model_kernel(_copy(model))
    assert all(_read_only_flags(kernel))
    assert _read_only_flags(copied) == _read_only_flags(kernel)


def test_a_pickled_model_runs_as_the_original():
    """The same motion, and the run of the copy compiles nothing the original's did not."""
    model = cmbs.load("slider-crank-joint")
    first = cmbs.simulate(model, t_end=0.2, integrator="rk4", dt=1e-3)
    again = cmbs.simulate(_copy(model), t_end=0.2, integrator="rk4", dt=1e-3)
    np.testing.assert_array_equal(again.q, first.q)
    assert again.info["compile_time"] == 0.0


class _Foreign:
    """An object of another package: its attributes are its own business, not walked."""

    def __init__(self, data):
        self.data = data


def test_paths_reach_arrays_in_dicts_lists_and_tuples():
    frozen, writeable, shared, foreign = np.zeros(3), np.ones(2), np.arange(4.0), np.ones(1)
    for array in (frozen, shared, foreign):
        array.setflags(write=False)
    graph = {"a": (writeable, frozen), "b": [shared], "c": shared, "d": _Foreign(foreign)}
    paths = read_only_paths(graph)
    assert sorted(paths) == sorted([(("item", "a"), ("item", 1)), (("item", "b"), ("item", 0))])
    copy = pickle.loads(pickle.dumps(graph))
    assert copy["a"][1].flags.writeable and copy["c"].flags.writeable     # numpy's pickle
    make_read_only(copy, paths)
    assert not copy["a"][1].flags.writeable and copy["a"][0].flags.writeable
    assert not copy["c"].flags.writeable and copy["c"] is copy["b"][0]  # shared, marked once
