"""Soft joint-limit errors of one tick: the compiled core against the Python specification.

For each built-in model, on the same seeded configurations: ``JointLimitSet.errors`` (Python,
the specification and the baseline) and ``JointLimitSet.compiled().errors`` (the compiled
core through its binding: a new numpy array per call), in alternating chunks so that both see
the same machine load. Two sets of configurations: near standing (steps of 0.1 rad: most
joints inside their limits, the cheap test only) and mixed (steps of 0.1–1.5 rad: many
joints past, the exact error too). Printed: p50 and p99 per call, the share of limited joints
past a limit, and the ratio of the Python p50 to the compiled one.

Usage: python bench/joint_limits_core.py [--calls 2000] [--chunks 4]
"""

from __future__ import annotations

from controller_server.blas import default_to_single_threaded_blas

default_to_single_threaded_blas()  # before numpy: see controller_server/blas.py

import argparse
import os

import numpy as np
import pinocchio as pin
from baselines import alternating_times

from controller_server.features.joint_limits import JointLimitSet, default_joint_limits
from controller_server.models import BUILTIN_MODELS, RobotModel, load_robot_model

WARMUP_CALLS = 100
STATE_SETS = {"near standing": (0.1,), "mixed": (0.1, 0.5, 1.5)}  # rad (m) of the step


def configurations(robot: RobotModel, count: int, spreads, rng: np.random.Generator) -> list:
    """Steps on the manifold from standing, of the given spreads."""
    model = robot.model
    return [
        pin.integrate(
            model,
            robot.standing_configuration,
            rng.normal(scale=rng.choice(spreads), size=model.nv),
        )
        for _ in range(count)
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=2000, help="configurations per model and set")
    parser.add_argument("--chunks", type=int, default=4, help="alternations of the variants")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; {args.calls} calls")
    header = f"{'model':<19}{'set':<15}{'past':>6}  {'variant':<10}{'p50 µs':>9}{'p99 µs':>9}"
    print(f"{header}{'python/it':>11}")
    for name in BUILTIN_MODELS:
        robot = load_robot_model(name)
        limit_set = JointLimitSet(default_joint_limits(robot), robot.model.nv)
        compiled = limit_set.compiled()
        variants = {"python": limit_set.errors, "compiled": compiled.errors}
        for set_name, spreads in STATE_SETS.items():
            states = configurations(robot, args.calls, spreads, rng)
            past = np.mean(
                [
                    limit.error(q) > 0.0
                    for q in states[: min(200, len(states))]
                    for limit in limit_set.limits
                ]
            )
            times = alternating_times(variants, states, args.chunks, WARMUP_CALLS)
            python50 = float(np.percentile(times["python"], 50))
            for label, samples in times.items():
                p50, p99 = np.percentile(samples, [50, 99])
                print(
                    f"{name:<19}{set_name:<15}{past:>6.0%}  {label:<10}{p50 * 1e6:>9.1f}"
                    f"{p99 * 1e6:>9.1f}{python50 / p50:>10.2f}x"
                )


if __name__ == "__main__":
    main()
