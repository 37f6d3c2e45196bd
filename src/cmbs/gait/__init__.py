"""Human gait on real recorded data (docs/gait.md).

:mod:`cmbs.gait.data` fetches and reads the public treadmill trial and the normative curves;
:mod:`cmbs.gait.reconstruct` turns one stride into a kinematically consistent reference motion
of the library's 14-DOF ``human`` model.  :func:`prepare_stride` chains them.
"""

from __future__ import annotations

from pathlib import Path

from cmbs.gait.data import NORMATIVE, TRIAL, GaitDataError, fetch, read_normative, read_trial
from cmbs.gait.reconstruct import INDEPENDENT, FitStatistics, Prepared, prepare

__all__ = ["GaitDataError", "INDEPENDENT", "FitStatistics", "Prepared", "prepare", "prepare_stride"]


def prepare_stride(stride: int = 1, *, cutoff: float = 6.0, cache: Path | None = None) -> Prepared:
    """Reference motion of right stride ``stride`` of the treadmill trial, on the library's
    ``human`` model scaled to the subject's recorded mass and height (fetches the data on first
    use into ``cache``, default ``$CMBS_CACHE`` or ``~/.cache/cmbs``)."""
    from cmbs.library import load_library_model

    trial = read_trial(fetch(TRIAL, cache))
    curves = read_normative(fetch(NORMATIVE, cache))
    model = load_library_model("human", body_mass=trial.body_mass, height=trial.height)
    return prepare(trial, curves, model, stride, cutoff=cutoff)
