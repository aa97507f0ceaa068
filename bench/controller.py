"""Per-tick compute time of the controllers against a floor measured in the same run.

For each built-in model: the `tracking` baseline, the `momentum` controller
(all objectives on) and the `prioritized` controller (de Lasa 2010, default
priorities), in-process (no network), each running its optimizer on every
tick (`optimizer_period_ticks = 1`), without diagnostics (as on the ticks
that carry none), on the same seeded states near standing (random pose,
velocities and contact flags: every tick is a fresh problem, as for a
stateless per-tick solver such as TSID). The momentum controller is also
timed on the recorded states of a real balance run under a push (the replay
fixture), where the perturbations are those of a run rather than random.

The floor, measured in the same run and in alternating chunks with the
controllers (so that both see the same machine load): Pinocchio's
`computeAllTerms` plus the centroidal map plus one DAQP solve of the size of
the momentum controller's problem (nv unknowns, 12 support equalities),
called directly. Every controller runs with each kernel side by side: `compiled` (the
weighted controllers' whole tick in C++, the prioritized controller's dynamics terms) and
`python` (the specification). Goals: issue 35's, the compiled `momentum` p50 ≤ 3× the
floor with its p99 ≤ 2× its p50; issue 15's, `prioritized` p50 ≤ 1 ms.

Usage: python bench/controller.py [--ticks 600] [--chunks 3]
"""

from __future__ import annotations

from controller_server.blas import default_to_single_threaded_blas

default_to_single_threaded_blas()  # before numpy: see controller_server/blas.py

import argparse
from pathlib import Path

import numpy as np
from baselines import Floor, timed

from clients.sampling import random_state
from controller_server.controllers import create_controller
from controller_server.models import BUILTIN_MODELS, load_robot_model
from controller_server.session import Session
from controller_server.wire import control_input_from_state
from protocol.messages import Hello, State
from protocol.recording import read_log

CONTROLLERS = ("tracking", "momentum", "prioritized")
RECORDED_STATES = Path(__file__).parent.parent / "tests" / "fixtures" / "replay_momentum_push.mcap"
KERNELS = ("compiled", "python")
MOMENTUM_GOAL_RATIO = 3.0
TAIL_GOAL_RATIO = 2.0
PRIORITIZED_GOAL_S = 1e-3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=600, help="random states per model")
    parser.add_argument("--chunks", type=int, default=3, help="alternations floor/controllers")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    print(
        f"{'model':<19}{'nv':>4}{'controller':>13}{'kernel':>10}{'states':>10}{'p50 µs':>9}"
        f"{'p99 µs':>9}"
        f"{'floor p50':>11}{'p50/floor':>11}{'p99/floor':>11}  goal"
    )
    for name in BUILTIN_MODELS:
        robot = load_robot_model(name)
        welcome = Session(Hello(model=name)).welcome(0)
        random_inputs = [
            control_input_from_state(robot, random_state(welcome, rng), want_diagnostics=False)[0]
            for _ in range(args.ticks)
        ]
        state_sets = {"random": random_inputs}
        if name == "thesis_humanoid" and RECORDED_STATES.exists():
            state_sets["recorded"] = [
                control_input_from_state(robot, entry.message, want_diagnostics=False)[0]
                for entry in read_log(RECORDED_STATES)
                if isinstance(entry.message, State)
            ]
        floor = Floor(robot.model, rng)
        runs = [
            (controller, kernel, label)
            for controller in CONTROLLERS
            for kernel in KERNELS
            for label in state_sets
            if label == "random" or controller == "momentum"
        ]
        controllers = {
            run: create_controller(
                run[0],
                robot,
                {"kernel": run[1]}
                | ({"optimizer_period_ticks": 1} if run[0] != "prioritized" else {}),
            )
            for run in runs
        }
        floor_times: list[float] = []
        times: dict[tuple[str, str], list[float]] = {run: [] for run in runs}
        for chunk in range(args.chunks):
            part = slice(chunk * args.ticks // args.chunks, (chunk + 1) * args.ticks // args.chunks)
            floor_times += timed(floor.tick, random_inputs[part])
            for run, controller in controllers.items():
                inputs = state_sets[run[2]]
                inputs = inputs[
                    chunk * len(inputs) // args.chunks : (chunk + 1) * len(inputs) // args.chunks
                ]
                times[run] += timed(controller.compute, inputs)
        floor50 = float(np.percentile(floor_times[5:], 50))
        floor99 = float(np.percentile(floor_times[5:], 99))
        for (controller, kernel, label), samples in times.items():
            p50, p99 = np.percentile(samples[5:], [50, 99])
            if controller == "momentum" and kernel == "compiled":
                met = p50 / floor50 <= MOMENTUM_GOAL_RATIO and p99 <= TAIL_GOAL_RATIO * p50
                goal = (
                    f"p50 ≤ {MOMENTUM_GOAL_RATIO:.0f}x floor, p99 ≤ {TAIL_GOAL_RATIO:.0f}x p50: "
                    + ("met" if met else "not met")
                )
            elif controller == "prioritized":
                goal = "p50 ≤ 1 ms: " + ("met" if p50 <= PRIORITIZED_GOAL_S else "not met")
            else:
                goal = ""
            print(
                f"{name:<19}{robot.model.nv:>4}{controller:>13}{kernel:>10}{label:>10}"
                f"{p50 * 1e6:>9.0f}"
                f"{p99 * 1e6:>9.0f}{floor50 * 1e6:>11.0f}{p50 / floor50:>10.1f}x"
                f"{p99 / floor99:>10.1f}x  {goal}"
            )


if __name__ == "__main__":
    main()
