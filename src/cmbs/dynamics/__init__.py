"""Forward-dynamics formulations, one module each behind the protocol of :mod:`cmbs.dynamics.base`.

``formulation("baumgarte", omega=20)`` builds one by its name; the names are those of the
command line: lagrange, baumgarte, penalty, matrix-r, projection, udwadia-kalaba.
"""

from __future__ import annotations

import dataclasses

from cmbs.dynamics.base import Accelerations, Formulation, Solver
from cmbs.dynamics.lagrange import Baumgarte, Lagrange
from cmbs.dynamics.matrix_r import MatrixR
from cmbs.dynamics.penalty import Penalty
from cmbs.dynamics.projection import Projection
from cmbs.dynamics.udwadia_kalaba import UdwadiaKalaba
from cmbs.errors import CmbsError, did_you_mean

FORMULATIONS: dict[str, type] = {cls.name: cls for cls in (Lagrange, Baumgarte, Penalty, MatrixR, Projection,
                                                           UdwadiaKalaba)}


def formulation(name: str, **options: object) -> Formulation:
    """The formulation called ``name`` with its ``options`` (CmbsError naming the valid ones)."""
    if name not in FORMULATIONS:
        raise CmbsError(f"unknown formulation {name!r}{did_you_mean(name, FORMULATIONS)}; choose one of "
                        f"{', '.join(FORMULATIONS)}")
    cls = FORMULATIONS[name]
    allowed = [field.name for field in dataclasses.fields(cls)]
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise CmbsError(f"formulation {name!r} has no option(s) {', '.join(unknown)}"
                        f"{did_you_mean(unknown, set(allowed) - set(options))} "
                        f"(options: {', '.join(allowed) or 'none'})")
    try:
        return cls(**options)
    except TypeError as error:
        raise CmbsError(f"formulation {name!r}: {error}") from None


__all__ = ["Accelerations", "Formulation", "Solver", "Lagrange", "Baumgarte", "Penalty", "MatrixR", "Projection",
           "UdwadiaKalaba", "FORMULATIONS", "formulation"]


def __getattr__(name: str) -> object:
    """Submodules on first use (PEP 562): ``cmbs.dynamics.field`` works after a plain ``import cmbs``."""
    from cmbs.lazy import submodule

    return submodule(__name__, name)
