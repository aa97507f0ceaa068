"""Real-time factor of the simulator client running against the server over ZeroMQ.

For each backend: quiet standing of the thesis humanoid for a few simulated
seconds with the server's `momentum` controller answering every 1 ms tick,
against two baselines measured in the same run: the backend stepping alone
(zero torques, no server), and the same loop with the optimizer every 5th
tick (the thesis runs it at 30–200 Hz; inverse dynamics still every tick).

Usage: python bench/sim_realtime.py [--seconds 2]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from clients.server_process import ServerProcess
from clients.sim.runner import make_backend, run_scenario, standing_state
from clients.sim.scenario import load_scenario


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
    print(f"{'backend':<11}{'physics alone':>15}{'server 1 kHz':>14}{'optimizer 200 Hz':>18}")
    with ServerProcess() as server:
        for backend in ("reference", "mujoco"):
            scenario = load_scenario("stand", backend=backend, duration_s=args.seconds)
            full = run_scenario(scenario, server.endpoint)
            decimated = run_scenario(
                scenario.model_copy(
                    update={"params": {**scenario.params, "optimizer_period_ticks": 5}}
                ),
                server.endpoint,
            )
            alone = physics_alone_rtf(scenario, full.welcome, args.seconds)
            full_rtf = f"{full.real_time_factor:.2f}x" + (" fell" if full.fell else "")
            decimated_rtf = f"{decimated.real_time_factor:.2f}x" + (
                " fell" if decimated.fell else ""
            )
            print(f"{backend:<11}{alone:>14.2f}x{full_rtf:>14}{decimated_rtf:>18}")
    print("real-time factor = simulated time / wall-clock time; ≥ 1 is real time")


if __name__ == "__main__":
    main()
