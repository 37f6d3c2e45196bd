"""Controllers in closed loop with any forward formulation: small callables u(t, q, q̇)."""

from cmbs.control.base import Reference, ZeroOrderHold
from cmbs.control.computed_torque import ComputedTorque
from cmbs.control.faults import ActuatorFault, SensorNoise, mass_fault
from cmbs.control.hybrid import ConstraintForceControl, Hybrid
from cmbs.control.pd import PD
from cmbs.control.pidc import PIDC
from cmbs.control.study import Fault, TrackingRun, format_table, robustness_study, track
from cmbs.control.udwadia_kalaba import (CirclePath, CoordinateOutput, FunctionOutput, TrackingTask,
                                         UdwadiaKalabaTracking, point_output)

__all__ = ["Reference", "ZeroOrderHold", "PD", "PIDC", "ComputedTorque", "Hybrid", "ConstraintForceControl",
           "UdwadiaKalabaTracking", "TrackingTask", "CirclePath", "CoordinateOutput", "FunctionOutput",
           "point_output", "ActuatorFault", "SensorNoise", "mass_fault", "Fault", "TrackingRun", "track",
           "robustness_study", "format_table"]
