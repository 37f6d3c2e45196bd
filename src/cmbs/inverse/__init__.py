"""Inverse dynamics: the forces that produce a prescribed motion."""

from cmbs.inverse.ida import InverseDynamics, inverse_dynamics

__all__ = ["InverseDynamics", "inverse_dynamics"]
