"""Inverse dynamics: the forces that produce a prescribed motion."""

from cmbs.inverse.ida import InverseDynamics, inverse_dynamics
from cmbs.inverse.projected import ControllabilityError, is_decoupled, passive_joint_torque, pidc_torque
from cmbs.inverse.reactions import joint_reaction_history, joint_reactions
from cmbs.inverse.servo import (LinePath, ServoConvergenceError, ServoOutput, ServoResult, callable_output,
                                coordinate_output, segment_point, servo_inverse_dynamics)
from cmbs.inverse.spatial_reactions import spatial_reactions
from cmbs.inverse.tree_reactions import tree_reactions

__all__ = ["InverseDynamics", "inverse_dynamics", "joint_reactions", "joint_reaction_history", "tree_reactions",
           "spatial_reactions",
           "pidc_torque", "passive_joint_torque", "is_decoupled", "ControllabilityError", "servo_inverse_dynamics",
           "ServoResult", "ServoOutput", "ServoConvergenceError", "segment_point", "coordinate_output",
           "callable_output", "LinePath"]
