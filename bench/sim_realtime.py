"""Real-time factor of the simulator client running against the server over ZeroMQ.

For each backend: quiet standing of the thesis humanoid for a few simulated
seconds with the server's `momentum` controller answering every 1 ms tick,
its optimizer running on every tick (the default, `optimizer_period_ticks =
1`; diagnostics every 10th tick): in lockstep (the simulator waits for each
command), pipelined (the command for tick k drives the physics from tick
k + 1, and the simulator steps while the server computes;
`command_delay_ticks = 1`), and both again at 200 Hz: the optimizer and the
diagnostics every 5th tick (the thesis runs its optimizer at 30–200 Hz, at
200 Hz in its experiments), inverse dynamics and a command every tick. The
baseline, measured in the same run, is the backend stepping alone (zero
torques, no server).

Usage: python bench/sim_realtime.py [--seconds 2]
"""

from __future__ import annotations

from controller_server.blas import default_to_single_threaded_blas

default_to_single_threaded_blas()  # before numpy: see controller_server/blas.py

import argparse
import time

import numpy as np

from clients.physics.status import standing_state
from clients.server_process import ServerProcess
from clients.sim.runner import make_backend, run_scenario
from clients.sim.scenario import Scenario, load_scenario


def physics_alone_rtf(scenario, welcome, seconds: float) -> float:
    backend = make_backend(scenario)
    backend.reset(standing_state(welcome, {}))
    torque = np.zeros(sum(j.nv for j in welcome.joints))
    steps = round(seconds * scenario.physics_rate_hz)
    start = time.perf_counter()
    for _ in range(steps):
        backend.step(torque, [])
    return seconds / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0)
    args = parser.parse_args()
    columns = {
        "lockstep": {"diagnostics_period_ticks": 10},
        "pipelined": {"command_delay_ticks": 1, "diagnostics_period_ticks": 10},
        "lockstep, 200 Hz": {"optimizer_period_ticks": 5, "diagnostics_period_ticks": 5},
        "pipelined, 200 Hz": {
            "command_delay_ticks": 1,
            "optimizer_period_ticks": 5,
            "diagnostics_period_ticks": 5,
        },
    }
    print(f"{'backend':<11}{'physics alone':>15}" + "".join(f"{c:>24}" for c in columns))
    with ServerProcess() as server:
        for backend in ("reference", "mujoco"):
            scenario = load_scenario("stand", backend=backend, duration_s=args.seconds)
            cells = []
            for overrides in columns.values():
                fields = {k: v for k, v in overrides.items() if k in Scenario.model_fields}
                params = {k: v for k, v in overrides.items() if k not in fields}
                run = run_scenario(
                    scenario.model_copy(update={"params": {**scenario.params, **params}, **fields}),
                    server.endpoint,
                )
                cells.append(f"{run.real_time_factor:.2f}x" + (" fell" if run.fell else ""))
            alone = physics_alone_rtf(scenario, run.welcome, args.seconds)
            print(f"{backend:<11}{alone:>14.2f}x" + "".join(f"{c:>24}" for c in cells))
    print("real-time factor = simulated time / wall-clock time; ≥ 1 is real time")
    print("issue 15 goal: MuJoCo lockstep (optimizer every tick) ≥ 1.0x on a quiet machine")


if __name__ == "__main__":
    main()
