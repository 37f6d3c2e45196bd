"""Fixed-step time grids."""

from __future__ import annotations

#: relative tolerance within which t_end counts as a whole number of steps dt
WHOLE_STEPS_TOLERANCE = 1e-9


def whole_steps(t_end: float, dt: float) -> int | None:
    """The number of steps dt that make t_end (to :data:`WHOLE_STEPS_TOLERANCE` relative), else
    None: a fixed-step loop can then end exactly at t_end."""
    steps = int(round(t_end / dt))
    return steps if abs(steps * dt - t_end) <= WHOLE_STEPS_TOLERANCE * t_end else None
