"""Inverse dynamics: the forces that produce a prescribed motion."""

from cmbs.inverse.ida import InverseDynamics, inverse_dynamics
from cmbs.inverse.projected import ControllabilityError, is_decoupled, passive_joint_torque, pidc_torque
from cmbs.inverse.reactions import joint_reaction_history, joint_reactions

__all__ = ["InverseDynamics", "inverse_dynamics", "joint_reactions", "joint_reaction_history", "pidc_torque",
           "passive_joint_torque", "is_decoupled", "ControllabilityError"]
