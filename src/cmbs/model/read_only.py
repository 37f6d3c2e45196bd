"""Pickling that keeps numpy arrays read-only.

A model marks its constant data read-only (``ndarray.setflags(write=False)``): the constant mass
matrix of natural coordinates, the packed kernel arrays of joint, spatial and robot models, the
start state.  The flag is part of what the compiled code sees — numba types a read-only array
apart from a writeable one, so each compiled loop is specialised (and cached) for it — and the
terms take a read-only M as constant.  numpy's pickle restores every array writeable, so a model
sent to a worker process of a sweep (:mod:`cmbs.sweep`: a process pool, a Dask cluster) would
come back with other types and compile every loop again in every worker.

:func:`read_only_paths` finds the read-only arrays of a model's object graph (through dicts,
lists, tuples and the attributes of cmbs's own objects), by the attribute names, keys and
indices that lead to them; :func:`make_read_only` marks them again after unpickling.
:class:`Model` pickles its state with the paths (``__getstate__``, ``__setstate__``).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

#: One step of a path: ("attribute", name) of an object (``__dict__`` or slots), ("item", key or index)
#: into a dict, list or tuple.
Step = tuple[str, Any]


def read_only_paths(root: object) -> list[tuple[Step, ...]]:
    """The paths from ``root`` to each read-only numpy array reachable through dicts, lists,
    tuples and the attributes of cmbs's own objects (``__dict__`` and slots).  Each object is
    visited once: a shared array is named by the first path that reaches it, and pickling keeps
    it shared."""
    return [path for path, array in _arrays(root, (), set()) if not array.flags.writeable]


def make_read_only(root: object, paths: list[tuple[Step, ...]]) -> None:
    """Mark the array at each of ``paths`` from ``root`` read-only."""
    for path in paths:
        target = root
        for kind, key in path:
            target = getattr(target, key) if kind == "attribute" else target[key]
        target.setflags(write=False)


def _arrays(value: object, path: tuple[Step, ...], seen: set[int]) -> Iterator[tuple[tuple[Step, ...], np.ndarray]]:
    if id(value) in seen:
        return
    seen.add(id(value))
    if isinstance(value, np.ndarray):
        yield path, value
    elif isinstance(value, dict):
        for key, item in value.items():
            yield from _arrays(item, path + (("item", key),), seen)
    elif isinstance(value, (list, tuple)):
        for index, item in enumerate(value):
            yield from _arrays(item, path + (("item", index),), seen)
    elif type(value).__module__.startswith("cmbs."):
        for name in _attribute_names(value):
            yield from _arrays(getattr(value, name), path + (("attribute", name),), seen)


def _attribute_names(value: object) -> list[str]:
    """The names of the attributes set on ``value``: its ``__dict__`` and its classes' slots."""
    names = list(getattr(value, "__dict__", {}))
    for kind in type(value).__mro__:
        slots = kind.__dict__.get("__slots__", ())
        names += [name for name in ((slots,) if isinstance(slots, str) else slots)
                  if name not in ("__dict__", "__weakref__") and hasattr(value, name)]
    return names
