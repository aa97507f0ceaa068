"""Seeded robot states shared by the compiled core's agreement tests.

One generator, so that every compiled step (the dynamics terms, the inverse dynamics, ...) is
held to its Python specification on the same kind of states.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from controller_server.models import RobotModel

CONFIGURATION_SPREADS = (0.1, 0.5, 1.5)  # rad (and m) of the step from standing
VELOCITY_SPREADS = (0.1, 1.0, 5.0)  # rad/s (and m/s)


def random_states(
    robot: RobotModel,
    count: int,
    seed: int = 0,
    configuration_spreads: Sequence[float] = CONFIGURATION_SPREADS,
    velocity_spreads: Sequence[float] = VELOCITY_SPREADS,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(q, v)``: standing at rest first, then a step on the manifold from standing and a
    velocity, each of a spread drawn from the given ones."""
    model = robot.model
    rng = np.random.default_rng(seed)
    states = [(robot.standing_configuration.copy(), np.zeros(model.nv))]
    while len(states) < count:
        step = rng.normal(scale=rng.choice(configuration_spreads), size=model.nv)
        q = pin.integrate(model, robot.standing_configuration, step)
        states.append((q, rng.normal(scale=rng.choice(velocity_spreads), size=model.nv)))
    return states
