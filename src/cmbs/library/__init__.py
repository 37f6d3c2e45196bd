"""The named models of cmbs: ``cmbs.load("four-bar")``, ``cmbs models`` lists them.

Each entry is a TOML file in this folder or a small builder function, and cites its source and
parameter values.  Builders take keyword parameters (``cmbs.load("chain", links=14)``).
"""

from __future__ import annotations

import functools
import inspect
from dataclasses import dataclass
from importlib import import_module, resources
from pathlib import Path
from typing import Callable

from cmbs.errors import ModelError, did_you_mean
from cmbs.model.limits import MAX_MAGNITUDE
from cmbs.model.model import Model


@dataclass(frozen=True)
class LibraryEntry:
    """A named model: one-line summary and a loader taking keyword parameters."""

    name: str
    summary: str
    loader: Callable[..., Model]

    def parameters(self) -> dict[str, object]:
        """The loader's keyword parameters and their defaults."""
        return {name: p.default for name, p in inspect.signature(self.loader).parameters.items()
                if p.default is not inspect.Parameter.empty}


def _file_loader(filename: str) -> Callable[[], Model]:
    def load() -> Model:
        from cmbs.model.files import load_model_file

        with resources.as_file(resources.files(__name__) / filename) as path:
            return load_model_file(Path(path))

    return load


@functools.cache
def _entries() -> dict[str, LibraryEntry]:
    """Every library entry by name, built once (its builders' modules imported, their signatures
    read), not on every :func:`entry` or :func:`check_parameters`."""
    entries: list[LibraryEntry] = []
    for filename, summary in _FILES:
        entries.append(LibraryEntry(filename.removesuffix(".toml"), summary, _file_loader(filename)))
    for name, module, function, summary in _BUILDERS:
        target = getattr(import_module(f"{__name__}.{module}"), function)
        entries.append(LibraryEntry(name, summary, target))
    return {entry.name: entry for entry in entries}


_FILES = [
    ("particle-circle.toml", "particle on a circle (Aghili 2005 §V-D), 1 DOF"),
    ("pendulum.toml", "simple pendulum, uniform rod 1 m 1 kg, 1 DOF"),
    ("double-pendulum.toml", "double pendulum of two uniform rods with angle coordinates, 2 DOF"),
    ("four-bar.toml", "thesis four-bar linkage, crank angle driven (fully driven, 0 DOF; 1 DOF undriven)"),
    ("five-bar-robot.toml", "robot (URDF, joint angles): planar five-bar parallel manipulator, 2 motors, 2 DOF"),
]
_BUILDERS = [
    ("chain", "chain", "chain", "N-link pendulum chain (links=N, closed=true pins the tip), N or N-2 DOF"),
    ("slider-crank", "mechanisms", "slider_crank",
     "Aghili's slider-crank, equal crank and rod, natural coordinates, 1 DOF"),
    ("slider-crank-joint", "mechanisms", "slider_crank_joint",
     "Aghili's slider-crank in joint angles (theta1, theta2), 1 DOF"),
    ("arm-on-slider", "mechanisms", "arm_on_slider",
     "Aghili's 3-link arm with its endpoint on a slider, joint angles, 2 DOF"),
    ("passive-manipulator", "mechanisms", "passive_manipulator",
     "3-link arm with passive third joint (Quasem et al.), natural coordinates, 3 DOF"),
    ("passive-manipulator-joint", "mechanisms", "passive_manipulator_joint",
     "3-link arm with passive third joint (Quasem et al.), joint angles, 3 DOF"),
    ("two-link-arm", "mechanisms", "two_link_arm",
     "fully actuated two-link arm (1 m, 1 kg rods, torques tau1, tau2), natural coordinates, 2 DOF"),
    ("two-link-arm-joint", "mechanisms", "two_link_arm_joint",
     "fully actuated two-link arm (1 m, 1 kg rods, torques tau1, tau2), joint angles, 2 DOF"),
    ("human", "human", "human", "12-segment 14-DOF planar human body (thesis Table 3.2), 38 coordinates"),
    ("chaplygin-sleigh", "mechanisms", "chaplygin_sleigh",
     "Chaplygin sleigh: rigid body with a knife edge (nonholonomic), 3 DOF, 2 velocity DOF"),
    ("andrews", "andrews", "andrews",
     "Andrews' squeezing mechanism (Hairer & Wanner's seven-body benchmark), relative angles, 1 DOF"),
    ("n-four-bar", "n_four_bar", "n_four_bar",
     "IFToMM A02 N-four-bar: N loops of 1 m, 1 kg bars, 1 DOF, N+1 DOF at its singular positions"),
    ("spherical-pendulum", "spatial", "spherical_pendulum",
     "spatial: point mass on a rod from a fixed pivot, 2 DOF"),
    ("heavy-top", "spatial", "heavy_top", "spatial: heavy symmetric top on a fixed point, 3 DOF"),
    ("four-bar-3d", "spatial", "four_bar_3d",
     "spatial: the thesis four-bar built in 3-D (plane y = 0), undriven, 1 DOF"),
    ("bricard", "spatial", "bricard",
     "spatial: IFToMM A04 Bricard's mechanism, five rods and six revolute joints, 1 DOF, redundant constraints"),
    ("spatial-slider-crank", "spatial", "spatial_slider_crank",
     "spatial: IFToMM slider-crank, revolute, spherical, universal and prismatic joints, 1 DOF"),
    ("flyball-governor", "spatial", "flyball_governor",
     "spatial: IFToMM A05 stiff flyball governor, shaft, slider, two rods with balls, stiff springs, 4 DOF"),
]


def names() -> list[str]:
    """Names of the library models, in listing order."""
    return list(_entries())


def entry(name: str) -> LibraryEntry:
    """The library entry ``name`` (ModelError listing the names otherwise)."""
    entries = _entries()
    if name not in entries:
        raise ModelError(f"no library model {name!r}; available: {', '.join(entries)}")
    return entries[name]


def load_library_model(name: str, **parameters: object) -> Model:
    """Build library model ``name`` with keyword ``parameters`` (checked against its loader)."""
    library_entry = entry(name)
    parameters = check_parameters(name, **parameters)
    from cmbs.model.files import assembled

    return assembled(library_entry.loader(**parameters), f"library model {name!r}")


def check_parameters(name: str, **parameters: object) -> dict[str, object]:
    """The keyword parameters of library model ``name`` as Python values (a numpy scalar becomes
    a bool, int or float); ModelError unless each is a parameter of the model with a value of its
    default's kind (:func:`_check_parameter`)."""
    allowed = entry(name).parameters()
    unknown = sorted(set(parameters) - set(allowed))
    if unknown:
        accepted = ", ".join(f"{k}={v!r}" for k, v in allowed.items()) or "none"
        hint = did_you_mean(unknown, set(allowed) - set(parameters))
        raise ModelError(f"model {name!r} has no parameter(s) {', '.join(unknown)}{hint} (parameters: {accepted})")
    return {key: _check_parameter(name, key, value, allowed[key]) for key, value in parameters.items()}


def _check_parameter(model: str, key: str, value: object, default: object) -> object:
    """``value`` as a Python value of its default's kind: true/false for a flag, a whole number for
    a count, a finite number for a quantity (a string such as "no" would otherwise count as true);
    other defaults take the value as it is."""
    import math
    import numbers

    import numpy as np

    flag = isinstance(value, (bool, np.bool_))
    if isinstance(default, bool):
        ok, kind, python = flag, "true or false", bool
    elif isinstance(default, int):
        ok, kind, python = isinstance(value, numbers.Integral) and not flag, "a whole number", int
    elif isinstance(default, float):
        ok = isinstance(value, numbers.Real) and not flag and math.isfinite(value)
        kind, python = "a finite number", float
    else:
        return value
    if not ok:
        raise ModelError(f"model {model!r}: parameter {key} must be {kind}, got {value!r}")
    if python is not bool and abs(value) > MAX_MAGNITUDE:
        raise ModelError(f"model {model!r}: parameter {key} = {value!r} is out of range: |{key}| must be <= "
                         f"{MAX_MAGNITUDE:g}")
    return python(value)


def __getattr__(name: str) -> object:
    """Submodules on first use (PEP 562): ``cmbs.library.NAME`` works after a plain ``import cmbs``."""
    from cmbs.lazy import submodule

    return submodule(__name__, name)
