"""Behaviours: state machines that set a controller's parameters from the robot's state.

de Lasa et al. build jumps and walks on the balance controller by changing
its objectives' references and weights from a state machine (§5–6). A
behaviour observes the tick's state (:class:`Observation`) and answers the
parameters to set now; the controller applies them as a ``set_params``
would, so every change is visible in the parameters in force.
"""

from controller_server.behaviors.jump import JUMP_PARAMETERS, StandingJump
from controller_server.behaviors.observation import Observation
from controller_server.behaviors.walk import WALK_PARAMETERS, Walk

__all__ = ["JUMP_PARAMETERS", "WALK_PARAMETERS", "Observation", "StandingJump", "Walk"]
