"""Thesis ch. 7.1 ablations: each momentum objective keeps the robot up under a push that
fells the controller without it, in both simulators.

The pushes are 0.1 s on the chest at t = 0.5 s, as in ``poise sim stand --sweep-push``,
sized between the survival thresholds that sweep's bisection found (docs/push-sweep.md),
with a margin on both sides: a bisection near a survival boundary moves by a few newtons
with round-off, so each push is at least 15 N from either threshold.
"""

import pytest

from clients.physics.backend import PushSpec
from clients.sim.runner import run_scenario
from clients.sim.scenario import load_scenario
from clients.sim.sweep import ABLATIONS

pytestmark = [pytest.mark.e2e, pytest.mark.slow]

DURATION_S = 2.5
"""Push at 0.5–0.6 s; a felled robot is down well before 2.5 s (checked by the sweep)."""


def fell(server, backend, ablation, force_in_world_N):
    push = PushSpec(body="chest", force_in_world_N=force_in_world_N, start_s=0.5, duration_s=0.1)
    scenario = load_scenario("stand", backend=backend, controller="momentum")
    scenario = scenario.model_copy(
        update={"params": ABLATIONS[ablation], "pushes": [push], "duration_s": DURATION_S}
    )
    record = run_scenario(scenario, server.endpoint)
    return record.fell


@pytest.mark.parametrize(
    ("backend", "force_in_world_N"),
    [
        # Sweep from the front: tracking only 125 N, + linear momentum 168 N (reference);
        # 117 N and 199 N (MuJoCo).
        ("reference", (-147.0, 0.0, 0.0)),
        ("mujoco", (-158.0, 0.0, 0.0)),
    ],
)
def test_linear_momentum_saves_what_tracking_alone_cannot(server, backend, force_in_world_N):
    """Eq. 5.9–5.10: steering the CM back over the feet adds robustness to a push from the
    front, which drives the CM over the heels."""
    assert fell(server, backend, "tracking only", force_in_world_N)
    assert not fell(server, backend, "+ linear momentum", force_in_world_N)


@pytest.mark.parametrize(
    ("backend", "force_in_world_N"),
    [
        # Sweep from the front: + linear momentum 168 N, + linear and angular 211 N (reference).
        ("reference", (-189.0, 0.0, 0.0)),
    ],
)
def test_angular_momentum_saves_what_linear_momentum_alone_cannot(
    server, backend, force_in_world_N
):
    """Eq. 5.15–5.17: with β_ba following the measured ‖p − g‖, damping the angular
    momentum keeps the robot up under a push that fells the linear objective alone."""
    assert fell(server, backend, "+ linear momentum", force_in_world_N)
    assert not fell(server, backend, "+ linear and angular momentum", force_in_world_N)
