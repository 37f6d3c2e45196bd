"""cmbs — simulation, inverse dynamics and control of constrained multibody systems.

The public API::

    model = cmbs.load("four-bar")                 # a library model, or a path to a TOML file
    q = cmbs.assemble(model)                      # position analysis
    motion = cmbs.kinematic_analysis(model, t)    # kinematics of a driven model
    motion.save("out.npz")
    run = cmbs.simulate(model.without_drivers(), t_end=5, formulation="projection")
"""

from pathlib import Path as _Path

from cmbs.dynamics import (Baumgarte, Lagrange, MatrixR, Penalty, Projection, UdwadiaKalaba, formulation)
from cmbs.errors import CmbsError, ConvergenceError, ExpressionError, ModelError, SingularSystemError
from cmbs.errors import did_you_mean as _did_you_mean
from cmbs.inputs import SampledInput
from cmbs.kinematics import (ConstraintReport, accelerations, assemble, constraint_report, kinematic_analysis,
                             singular_configurations, velocities)
from cmbs.model.drivers import Constant, Expression, PythonFunction, Table
from cmbs.model.model import Model, Terms
from cmbs.model.natural import NaturalModelBuilder
from cmbs.model.spatial import SpatialModelBuilder
from cmbs.simulate import simulate
from cmbs.sweep import SweepResult, Variant, grid, sweep
from cmbs.trajectory import Trajectory

__version__ = "0.1.0"

_ON_FIRST_USE = {"InverseDynamics": "cmbs.inverse", "inverse_dynamics": "cmbs.inverse"}


def __getattr__(name: str) -> object:
    """Names whose modules are imported on first use (PEP 562), so that a simulation does not
    import what it never calls: the names of ``_ON_FIRST_USE`` and every submodule
    (``cmbs.inverse``, ``cmbs.control``, ...)."""
    if name in _ON_FIRST_USE:
        import importlib

        return getattr(importlib.import_module(_ON_FIRST_USE[name]), name)
    from cmbs.lazy import submodule

    return submodule(__name__, name)


def load(name_or_path: str | _Path, **parameters: object) -> Model:
    """A model by library name (``cmbs models`` lists them), from a TOML model file or from a URDF
    robot file (``*.urdf``, :func:`cmbs.model.urdf.load_urdf`).

    The returned model is assembled: ``model.q0`` satisfies Φ(q0, 0) = 0 and ``model.qd0`` the
    velocity constraints.  ``parameters`` go to library builders (e.g. ``links=14``).
    """
    from cmbs.library import load_library_model, names
    from cmbs.model.files import load_model_file

    text = str(name_or_path)
    if text in names():
        return load_library_model(text, **parameters)
    if parameters:
        raise ModelError(f"parameters {sorted(parameters)} apply to library models only, not to files",
                         source=text)
    if text.lower().endswith(".urdf"):
        from cmbs.model.urdf import load_urdf

        return load_urdf(text)
    if text.endswith(".toml") or _Path(text).exists():
        return load_model_file(text)
    raise ModelError(f"no library model or file {text!r}{_did_you_mean(text, names())}; library models: "
                     f"{', '.join(names())}")


__all__ = [
    "CmbsError", "ConvergenceError", "ExpressionError", "ModelError", "SingularSystemError",
    "ConstraintReport", "accelerations", "assemble", "constraint_report", "kinematic_analysis",
    "singular_configurations", "velocities", "Constant", "Expression", "PythonFunction", "Table",
    "Model", "Terms", "NaturalModelBuilder", "SpatialModelBuilder", "Trajectory", "load", "simulate", "SampledInput", "formulation",
    "Lagrange", "Baumgarte", "Penalty", "MatrixR", "Projection", "UdwadiaKalaba", "InverseDynamics",
    "inverse_dynamics", "sweep", "Variant", "grid", "SweepResult",
]
