"""Human gait on real recorded data (docs/gait.md).

:mod:`cmbs.gait.data` fetches and reads the public treadmill trial and the normative curves;
:mod:`cmbs.gait.reconstruct` turns one stride into a kinematically consistent reference motion
of the library's 14-DOF ``human`` model.  :func:`prepare_stride` chains them.
:mod:`cmbs.gait.inverse` computes the stride's inverse dynamics, :mod:`cmbs.gait.track` its
forward dynamics (open-loop replay, PD and computed-torque tracking, robustness studies).
"""

from __future__ import annotations

from pathlib import Path

from cmbs.gait.data import NORMATIVE, TRIAL, GaitDataError, fetch, read_normative, read_trial
from cmbs.gait.reconstruct import INDEPENDENT, FitStatistics, Prepared, prepare, subject_lengths

__all__ = ["GaitDataError", "INDEPENDENT", "FitStatistics", "Prepared", "prepare", "prepare_stride",
           "subject_lengths"]


def prepare_stride(stride: int = 1, *, cutoff: float = 6.0, cache: Path | None = None,
                   subject_specific: bool = True) -> Prepared:
    """Reference motion of right stride ``stride`` of the treadmill trial, on the library's
    ``human`` model scaled to the subject's recorded mass and height, with the trunk, thigh,
    shank and foot lengths measured on the subject (:func:`subject_lengths`) unless
    ``subject_specific`` is false (fetches the data on first use into ``cache``, default
    ``$CMBS_CACHE`` or ``~/.cache/cmbs``)."""
    from cmbs.library import load_library_model

    trial = read_trial(fetch(TRIAL, cache))
    curves = read_normative(fetch(NORMATIVE, cache))
    lengths = subject_lengths(trial) if subject_specific else None
    model = load_library_model("human", body_mass=trial.body_mass, height=trial.height, lengths=lengths)
    return prepare(trial, curves, model, stride, cutoff=cutoff)


def __getattr__(name: str) -> object:
    """Submodules on first use (PEP 562): ``cmbs.gait.NAME`` works after a plain ``import cmbs``."""
    from cmbs.lazy import submodule

    return submodule(__name__, name)
