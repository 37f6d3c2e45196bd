"""The SI unit of a model's coordinates and of the generalized forces conjugate to them.

A generalized force τ on coordinate q does the virtual work τ δq [J], so its unit is J divided
by the coordinate's: N m on an angle (rad), N on a length (m).  Natural coordinates say what each
coordinate is (:attr:`~cmbs.model.model.Model.coordinate_kinds`: x, y, z, distance, angle; the
components of a spatial unit vector, kind ``direction``, have no unit), joint coordinates by
their joint (revolute or prismatic); a model from the user's own equations (kind ``generic``)
does not say, and the unit is then ``""``.
"""

from __future__ import annotations

from cmbs.model.model import Model

ANGLE, LENGTH = "rad", "m"
#: the unit of the generalized force on a coordinate of each unit
FORCE = {ANGLE: "N m", LENGTH: "N"}
_KINDS = {"angle": ANGLE, "x": LENGTH, "y": LENGTH, "z": LENGTH, "distance": LENGTH}


def coordinate_unit(model: Model, name: str) -> str:
    """``"rad"`` or ``"m"`` for coordinate ``name`` of ``model``, ``""`` when the model does not
    say (its own equations)."""
    index = model.coordinate_index(name)
    kind = model.coordinate_kinds[index]
    if kind == "joint":
        layout = _joint_layout(model)
        return "" if layout is None else ANGLE if layout.revolute[index] else LENGTH
    return _KINDS.get(kind, "")


def force_unit(model: Model, name: str) -> str:
    """``"N m"`` on an angle, ``"N"`` on a length, ``""`` when the coordinate's unit is unknown."""
    return FORCE.get(coordinate_unit(model, name), "")


def bracketed(unit: str) -> str:
    """`` [unit]`` for a label, nothing for an unknown unit."""
    return f" [{unit}]" if unit else ""


def _joint_layout(model: Model):
    """The joint layout of a joint-coordinate model's equations (also under wrappers that keep
    its coordinates, e.g. a prescribed motion), or None."""
    equations = model.equations
    while equations is not None:
        if hasattr(equations, "layout"):
            return equations.layout()
        equations = getattr(equations, "inner", None)
    return None
