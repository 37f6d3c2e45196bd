"""Modules imported on first use, so that ``import cmbs`` does not pay for what a run may never
call (scipy's linalg, interpolate, optimize and sparse take about 0.3 s to import, more than a
compiled 10 s simulation of a small mechanism).

:func:`on_first_use` stands for a module of another package inside cmbs: its first attribute read
imports the module in the usual way, so a program that imports cmbs finds in ``sys.modules`` and on
the parent package exactly what a plain import puts there.  :func:`submodule` serves a package's
module ``__getattr__``.
"""

from __future__ import annotations

import importlib
import importlib.util
from types import ModuleType


class on_first_use:  # noqa: N801 -- used like a module: ``linalg = on_first_use("scipy.linalg")``
    """The module ``name``, imported by a plain import at the first attribute read through this
    object, which then forwards every attribute read to the module.  It is no module and is put
    nowhere: ``sys.modules`` and the parent package are left to the import system."""

    def __init__(self, name: str) -> None:
        self._name = name
        self._module: ModuleType | None = None

    def __getattr__(self, attribute: str) -> object:
        if self._module is None:
            self._module = importlib.import_module(self._name)
        return getattr(self._module, attribute)

    def __repr__(self) -> str:
        return f"<{self._name}, imported on first use>"


def submodule(package: str, name: str) -> ModuleType:
    """The submodule ``package.name``, imported now: a package's module ``__getattr__`` (PEP 562)
    returns it, so that ``cmbs.model.joints`` works after a plain ``import cmbs`` as it does after
    ``import cmbs.model.joints``, and ``import cmbs`` imports neither.  AttributeError, as for any
    missing attribute, when the package has no such submodule."""
    if not name.startswith("__") and importlib.util.find_spec(f"{package}.{name}") is not None:
        return importlib.import_module(f"{package}.{name}")
    raise AttributeError(f"module {package!r} has no attribute {name!r}")
