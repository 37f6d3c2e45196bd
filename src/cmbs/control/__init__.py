"""Controllers in closed loop with any forward formulation: small callables u(t, q, q̇)."""

from cmbs.control.base import Reference, ZeroOrderHold
from cmbs.control.computed_torque import ComputedTorque
from cmbs.control.faults import ActuatorFault, SensorNoise, mass_fault
from cmbs.control.pd import PD
from cmbs.control.pidc import PIDC

__all__ = ["Reference", "ZeroOrderHold", "PD", "PIDC", "ComputedTorque", "ActuatorFault", "SensorNoise", "mass_fault"]
