"""The dynamics terms of one tick: the compiled core against the Python specification.

For each built-in model, on the same seeded states (a step on the manifold from standing and
a velocity, of mixed spreads): ``compute_dynamics_terms`` (Python, the specification and the
baseline) and ``CompiledDynamics.compute`` (the compiled core, what a controller with
``kernel = "compiled"`` calls: the core, the ``DynamicsTerms`` around its arrays, and the
kinematics left in the Pinocchio data), in alternating chunks so that both see the same
machine load. Also the core's own call (``Core.compute``: fresh arrays in a dict).
Printed: p50 and p99 per call and the ratio of the Python p50 to each.

Usage: python bench/dynamics_core.py [--calls 2000] [--chunks 4]
"""

from __future__ import annotations

from controller_server.blas import default_to_single_threaded_blas

default_to_single_threaded_blas()  # before numpy: see controller_server/blas.py

import argparse
import os
from collections.abc import Callable

import numpy as np
import pinocchio as pin
from baselines import alternating_times

from controller_server.compiled import load_core
from controller_server.dynamics import CompiledDynamics, compute_dynamics_terms
from controller_server.models import BUILTIN_MODELS, RobotModel, load_robot_model

WARMUP_CALLS = 100


def random_states(robot: RobotModel, count: int, rng: np.random.Generator) -> list:
    """``(q, v)`` pairs: steps of 0.1–1.5 from standing, velocities of 0.1–5 per DoF."""
    model, states = robot.model, []
    for _ in range(count):
        step = rng.normal(scale=rng.choice([0.1, 0.5, 1.5]), size=model.nv)
        q = pin.integrate(model, robot.standing_configuration, step)
        states.append((q, rng.normal(scale=rng.choice([0.1, 1.0, 5.0]), size=model.nv)))
    return states


def calls(robot: RobotModel) -> dict[str, Callable[[tuple], object]]:
    """Each variant as a call on one ``(q, v)``, with its own workspace."""
    data = robot.model.createData()
    compiled = CompiledDynamics(robot)
    core = load_core().Core(
        robot.model.saveToString(),
        [c.frame_id for c in robot.contacts],
        [np.ascontiguousarray(c.points_in_frame, dtype=float) for c in robot.contacts],
    )
    return {
        "python": lambda state: compute_dynamics_terms(robot, data, *state),
        "compiled": lambda state: compiled.compute(data, *state),
        "core alone": lambda state: core.compute(*state),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=2000, help="states per model")
    parser.add_argument("--chunks", type=int, default=4, help="alternations of the variants")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; {args.calls} calls")
    print(f"{'model':<19}{'nv':>4}  {'variant':<12}{'p50 µs':>9}{'p99 µs':>9}{'python/it':>11}")
    for name in BUILTIN_MODELS:
        robot = load_robot_model(name)
        variants = calls(robot)
        states = random_states(robot, args.calls, rng)
        times = alternating_times(variants, states, args.chunks, WARMUP_CALLS)
        python50 = float(np.percentile(times["python"], 50))
        for label, samples in times.items():
            p50, p99 = np.percentile(samples, [50, 99])
            print(
                f"{name:<19}{robot.model.nv:>4}  {label:<12}{p50 * 1e6:>9.1f}{p99 * 1e6:>9.1f}"
                f"{python50 / p50:>10.2f}x"
            )


if __name__ == "__main__":
    main()
