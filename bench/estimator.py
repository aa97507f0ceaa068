"""What estimating the base costs a session: a state with ``imu`` against one with the base.

For the `momentum` and `prioritized` controllers on the thesis humanoid, in-process (no
network), two sessions answer the same ticks of a robot standing, its joints and contact
flags alike: one is given the base pose and twist, the other a noisy, biased IMU reading
(BMI088 figures) from which it estimates them (issue 17). Printed: each session's tick
(p50, p99), the estimator alone, and the ratio of the IMU tick to the base tick, measured
in alternating chunks so that both see the same machine load.

Usage: python bench/estimator.py [--ticks 600] [--chunks 3]
"""

from __future__ import annotations

from controller_server.blas import default_to_single_threaded_blas

default_to_single_threaded_blas()  # before numpy: see controller_server/blas.py

import argparse

import numpy as np
from baselines import timed

from clients.state import RobotState
from controller_server.session import Session
from protocol.messages import Hello, ImuSample, State

GYRO_NOISE_RAD_PER_S = np.deg2rad(0.014) * np.sqrt(1000.0)
ACCEL_NOISE_M_PER_S2 = 175e-6 * 9.80665 * np.sqrt(1000.0)


def imu_states(standing: RobotState, ticks: int, rng: np.random.Generator) -> list[State]:
    """A still robot's IMU at 1 kHz: white noise on a fixed bias (BMI088 orders of magnitude)."""
    gyro_bias, accel_bias = rng.normal(0, 0.01, 3), rng.normal(0, 0.1, 3)
    states = []
    for tick in range(ticks):
        sample = ImuSample(
            angular_velocity_imu_in_imu=gyro_bias + rng.normal(0, GYRO_NOISE_RAD_PER_S, 3),
            linear_acceleration_imu_in_imu=np.array([0.0, 0.0, 9.80665])
            + accel_bias
            + rng.normal(0, ACCEL_NOISE_M_PER_S2, 3),
        )
        states.append(standing.to_imu_message(tick * 1e-3, [True, True], sample))
    return states


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=600, help="ticks per session")
    parser.add_argument("--chunks", type=int, default=3, help="alternations of the sessions")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    print(f"{'controller':<13}{'state':<8}{'p50 µs':>9}{'p99 µs':>9}{'vs base':>9}")
    for controller in ("momentum", "prioritized"):
        with_base = Session(Hello(model="thesis_humanoid", controller=controller))
        with_imu = Session(Hello(model="thesis_humanoid", controller=controller))
        standing = RobotState.standing(with_base.welcome(0))
        imu = imu_states(standing, args.ticks, rng)
        base = [standing.to_message(m.time_s, [True, True]) for m in imu]
        times: dict[str, list[float]] = {"base": [], "imu": [], "estimator": []}
        estimator = Session(Hello(model="thesis_humanoid")).base_estimator
        for chunk in range(args.chunks):
            part = slice(chunk * args.ticks // args.chunks, (chunk + 1) * args.ticks // args.chunks)
            times["base"] += timed(with_base.step, base[part])
            times["imu"] += timed(with_imu.step, imu[part])
            times["estimator"] += timed(estimator, imu[part])
        base50 = float(np.percentile(times["base"][5:], 50))
        for label in ("base", "imu", "estimator"):
            p50, p99 = np.percentile(times[label][5:], [50, 99])
            print(
                f"{controller:<13}{label:<10}{p50 * 1e6:>7.0f}{p99 * 1e6:>9.0f}"
                f"{p50 / base50:>8.2f}x"
            )


if __name__ == "__main__":
    main()
