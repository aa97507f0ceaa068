"""Per-tick compute time of the controllers against a same-run baseline.

For each built-in model: the `momentum` controller (all objectives on), the
`tracking` baseline controller and the `prioritized` controller (de Lasa
2010, default priorities), in-process (no network), on 1,000 seeded states
near standing (the prioritized one on the first fifth: it is the slow one).
Baseline, measured in the same run on the same states: Pinocchio's dynamics
terms (`computeAllTerms`) plus one dense QP of the same size as the
controller's problem (nv unknowns, 12 support equalities), solved by ProxQP
through qpsolvers.

Usage: python bench/controller.py [--ticks 1000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pinocchio as pin
import qpsolvers

from clients.sampling import random_state
from controller_server.controllers import create_controller
from controller_server.models import BUILTIN_MODELS, load_robot_model
from controller_server.session import Session
from controller_server.wire import control_input_from_state
from protocol.messages import Hello


def percentiles(samples: list[float]) -> tuple[float, float]:
    return float(np.percentile(samples, 50)), float(np.percentile(samples, 99))


def baseline_tick(model, data, q, v, P, c, C, d) -> None:
    pin.computeAllTerms(model, data, q, v)
    qpsolvers.solve_qp(P, c, A=C, b=d, solver="proxqp")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=1000)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    header = f"{'model':<19}{'nv':>4}{'controller':>12}{'p50 µs':>9}{'p99 µs':>9}"
    header += f"{'base p50':>10}{'base p99':>10}{'p50 ratio':>11}{'p99 ratio':>11}"
    print(header)
    for name in BUILTIN_MODELS:
        robot = load_robot_model(name)
        model = robot.model
        welcome = Session(Hello(model=name)).welcome(0)
        inputs = [
            control_input_from_state(robot, random_state(welcome, rng)) for _ in range(args.ticks)
        ]
        data = model.createData()
        P = np.eye(model.nv) + 0.1 * np.ones((model.nv, model.nv))
        C = rng.normal(size=(12, model.nv))
        base = []
        for control_input in inputs:
            c, d = rng.normal(size=model.nv), rng.normal(size=12)
            start = time.perf_counter()
            baseline_tick(model, data, control_input.q, control_input.v, P, c, C, d)
            base.append(time.perf_counter() - start)
        base50, base99 = percentiles(base[10:])
        for controller_name in ("tracking", "momentum", "prioritized"):
            controller = create_controller(controller_name, robot, {})
            times = []
            ticks = (
                inputs if controller_name != "prioritized" else inputs[: max(20, args.ticks // 5)]
            )
            for control_input in ticks:
                start = time.perf_counter()
                controller.compute(control_input)
                times.append(time.perf_counter() - start)
            p50, p99 = percentiles(times[10:])
            ratios = f"{p50 / base50:>10.1f}x{p99 / base99:>10.1f}x"
            print(
                f"{name:<19}{model.nv:>4}{controller_name:>12}{p50 * 1e6:>9.0f}{p99 * 1e6:>9.0f}"
                f"{base50 * 1e6:>10.0f}{base99 * 1e6:>10.0f}{ratios}"
            )


if __name__ == "__main__":
    main()
