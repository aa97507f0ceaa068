"""Behaviours: state machines that drive a controller's tasks from the robot's state.

de Lasa et al. build jumps and walks on the balance controller by changing its objectives'
references, weights and priorities from a state machine (§5–6). A behaviour observes the
tick (:class:`Observation`) and answers its :class:`Targets` for that tick; the controller
that hosts it (the one whose ``behavior`` parameter names it) applies them for that tick
only (:mod:`controller_server.behaviors.behavior`).
"""

from controller_server.behaviors.behavior import Behavior, FeetFromCom, Targets
from controller_server.behaviors.jump import JUMP_PARAMETERS, StandingJump
from controller_server.behaviors.observation import Observation
from controller_server.behaviors.sway import SWAY_PARAMETERS, Sway
from controller_server.behaviors.walk import WALK_PARAMETERS, Walk
from controller_server.params import ParamSpec

__all__ = [
    "BEHAVIORS",
    "JUMP_PARAMETERS",
    "SWAY_PARAMETERS",
    "WALK_PARAMETERS",
    "Behavior",
    "FeetFromCom",
    "Observation",
    "StandingJump",
    "Sway",
    "Targets",
    "Walk",
    "behavior_parameters",
]

BEHAVIORS: dict[str, type[Behavior]] = {
    behavior.name: behavior for behavior in (StandingJump, Walk, Sway)
}
"""Every behaviour by the name ``behavior`` gives it."""


def behavior_parameters(controller: str) -> dict[str, ParamSpec]:
    """``behavior`` and the parameters of every behaviour ``controller`` can host."""
    hosted = [name for name, behavior in BEHAVIORS.items() if controller in behavior.HOSTS]
    documented = "; ".join(f"`{name}`: {BEHAVIORS[name].SUMMARY}" for name in hosted)
    parameters = {
        "behavior": ParamSpec(
            "balance",
            kind="choice",
            choices=("balance", *BEHAVIORS),
            doc=f"{documented}; `balance` ends the behaviour and gives back every parameter "
            "it set (set a behaviour again to start it again). A behaviour this controller "
            "cannot host is refused",
        )
    }
    for name in hosted:
        parameters.update(BEHAVIORS[name].PARAMETERS)
    return parameters
