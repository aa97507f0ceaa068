"""What estimating the base costs a session: a state with ``imu`` against one with the base.

For the `momentum` and `prioritized` controllers on the thesis humanoid, in-process (no
network), two sessions answer the same ticks of a robot standing, its joints and contact
flags alike: one is given the base pose and twist, the other a noisy, biased IMU reading
(BMI088 figures) from which it estimates them (issue 17). Printed: each session's tick
(p50, p99), the estimator alone by each kernel (``ImuBaseEstimator`` with ``kernel =
"python"``, the specification, and ``"compiled"``, the C++ core), and the ratio of each
to the base tick, measured in alternating chunks so that all see the same machine load;
then the two estimator ticks side by side and issue 35's goal 3 (an estimator tick
≤ 30 µs), met or not.

Usage: python bench/estimator.py [--ticks 600] [--chunks 3]
"""

from __future__ import annotations

from controller_server.blas import default_to_single_threaded_blas

default_to_single_threaded_blas()  # before numpy: see controller_server/blas.py

import argparse
from functools import partial

import numpy as np
from baselines import timed

from clients.state import RobotState
from controller_server.session import Session
from protocol.messages import Hello, ImuSample, State

GOAL_ESTIMATOR_TICK_S = 30e-6
"""Issue 35, goal 3: one estimator tick."""
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
    print(f"{'controller':<13}{'state':<21}{'p50 µs':>9}{'p99 µs':>9}{'vs base':>9}")
    estimator_times: dict[str, list[float]] = {"python": [], "compiled": []}
    for controller in ("momentum", "prioritized"):
        with_base = Session(Hello(model="thesis_humanoid", controller=controller))
        with_imu = Session(Hello(model="thesis_humanoid", controller=controller))
        standing = RobotState.standing(with_base.welcome(0))
        imu = imu_states(standing, args.ticks, rng)
        base = [standing.to_message(m.time_s, [True, True]) for m in imu]
        times: dict[str, list[float]] = {"base": [], "imu": []}
        estimators = {
            kernel: partial(Session(Hello(model="thesis_humanoid")).base_estimator, kernel=kernel)
            for kernel in ("python", "compiled")
        }
        for kernel in estimators:
            times[f"estimator ({kernel})"] = []
        for chunk in range(args.chunks):
            part = slice(chunk * args.ticks // args.chunks, (chunk + 1) * args.ticks // args.chunks)
            times["base"] += timed(with_base.step, base[part])
            times["imu"] += timed(with_imu.step, imu[part])
            for kernel, estimator in estimators.items():
                times[f"estimator ({kernel})"] += timed(estimator, imu[part])
        for kernel in estimators:
            estimator_times[kernel] += times[f"estimator ({kernel})"][5:]
        base50 = float(np.percentile(times["base"][5:], 50))
        for label, values in times.items():
            p50, p99 = np.percentile(values[5:], [50, 99])
            print(
                f"{controller:<13}{label:<21}{p50 * 1e6:>7.0f}{p99 * 1e6:>9.0f}"
                f"{p50 / base50:>8.2f}x"
            )
    (python50, python99), (compiled50, compiled99) = (
        np.percentile(estimator_times[kernel], [50, 99]) for kernel in ("python", "compiled")
    )
    print(
        f"\nestimator tick, both sessions' ticks: python p50 {python50 * 1e6:.0f} µs, p99 "
        f"{python99 * 1e6:.0f} µs; compiled p50 {compiled50 * 1e6:.1f} µs, p99 "
        f"{compiled99 * 1e6:.1f} µs; python / compiled {python50 / compiled50:.0f}× (p50), "
        f"{python99 / compiled99:.0f}× (p99)"
    )
    verdict = {True: "met", False: "NOT met"}
    print(
        f"goal 3 (issue 35), an estimator tick ≤ {GOAL_ESTIMATOR_TICK_S * 1e6:.0f} µs: "
        f"p50 {verdict[compiled50 <= GOAL_ESTIMATOR_TICK_S]}, "
        f"p99 {verdict[compiled99 <= GOAL_ESTIMATOR_TICK_S]}"
    )


if __name__ == "__main__":
    main()
