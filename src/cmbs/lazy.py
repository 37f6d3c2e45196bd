"""Modules imported on first use, so that ``import cmbs`` does not pay for what a run may never
call (scipy's linalg, interpolate, optimize and sparse take about 0.3 s to import, more than a
compiled 10 s simulation of a small mechanism).

:func:`lazy_module` is the recipe of the Python documentation for
:class:`importlib.util.LazyLoader`: the module object exists at once and its code runs at the
first attribute access.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from types import ModuleType


def lazy_module(name: str) -> ModuleType:
    """The module ``name``, imported when one of its attributes is first read (at once if it was
    already imported)."""
    module = sys.modules.get(name)
    if module is not None:
        return module
    spec = importlib.util.find_spec(name)
    if spec is None or spec.loader is None:
        raise ImportError(f"no module named {name!r}")
    loader = importlib.util.LazyLoader(spec.loader)
    spec.loader = loader
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    loader.exec_module(module)
    parent, _, child = name.rpartition(".")
    if parent:      # bound to its package, as the import system binds a submodule it imports
        setattr(sys.modules[parent], child, module)
    return module


def submodule(package: str, name: str) -> ModuleType:
    """The submodule ``package.name``, imported now: a package's module ``__getattr__`` (PEP 562)
    returns it, so that ``cmbs.model.joints`` works after a plain ``import cmbs`` as it does after
    ``import cmbs.model.joints``, and ``import cmbs`` imports neither.  AttributeError, as for any
    missing attribute, when the package has no such submodule."""
    if not name.startswith("__") and importlib.util.find_spec(f"{package}.{name}") is not None:
        return importlib.import_module(f"{package}.{name}")
    raise AttributeError(f"module {package!r} has no attribute {name!r}")
