"""The inverse dynamics step: the compiled core against the Python specification.

For each built-in model, on two states: standing at rest on both feet with ``q̈ = 0``
(the exact case: minimum-norm forces, no QP) and a state near standing whose requested
``q̈`` pushes the centre of pressure off the feet (a QP case). Timed on the same terms
(``compute_dynamics_terms``), in alternating chunks so that all see the same load:

* ``python daqp``: ``solve_inverse_dynamics`` with ``qp_solver="daqp"`` (kernel "python" only);
* ``python quadprog``: the same with ``qp_solver="quadprog"``, the controllers' default and the
  compiled core's method (Goldfarb–Idnani; eiquadprog in C++);
* ``compiled``: ``_core.InverseDynamics.solve`` from Python: the DynamicsTerms copied into
  C++ (about 30 µs, which the compiled tick, holding its terms in C++, does not spend),
  fresh arrays out;
* ``C++ alone``: the C++ solve without Python (``InverseDynamics.time_solve``, one call
  timed at a time in C++).

Printed: p50 and p99 per call, and the ratio of the ``python daqp`` p50 to each.

Usage: python bench/inverse_dynamics_core.py [--calls 2000] [--chunks 4]
"""

from __future__ import annotations

from controller_server.blas import default_to_single_threaded_blas

default_to_single_threaded_blas()  # before numpy: see controller_server/blas.py

import argparse
import os

import numpy as np
import pinocchio as pin
from baselines import timed

from controller_server.compiled import load_core
from controller_server.dynamics import DynamicsTerms, compute_dynamics_terms
from controller_server.inverse_dynamics import solve_inverse_dynamics
from controller_server.models import BUILTIN_MODELS, RobotModel, load_robot_model

WARMUP_CALLS = 100
BOTH_FEET = (True, True)


def states(robot: RobotModel) -> dict[str, tuple[DynamicsTerms, np.ndarray]]:
    """``standing`` (exact case) and ``qp`` (a seeded state the exact case cannot realize)."""
    model = robot.model
    data = model.createData()
    standing = compute_dynamics_terms(robot, data, robot.standing_configuration, np.zeros(model.nv))
    rng = np.random.default_rng(0)
    solver = compiled(robot)
    mus = [c.friction_coefficient for c in robot.contacts]
    while True:  # near standing, a large q̈: the first that needs the condensed QP
        q = pin.integrate(
            model, robot.standing_configuration, rng.normal(scale=0.05, size=model.nv)
        )
        terms = compute_dynamics_terms(robot, data, q, rng.normal(scale=0.5, size=model.nv))
        desired = rng.normal(scale=10.0, size=model.nv)
        if solver.solve(terms, desired, BOTH_FEET, mus)["path"] == "condensed_qp":
            break
    return {"standing": (standing, np.zeros(model.nv)), "qp": (terms, desired)}


def compiled(robot: RobotModel):
    return load_core().InverseDynamics(
        robot.model.nv, [len(c.points_in_frame) for c in robot.contacts], robot.torque_limit
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=2000, help="calls per state and variant")
    parser.add_argument("--chunks", type=int, default=4, help="alternations of the variants")
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; {args.calls} calls")
    print(
        f"{'model':<19}{'nv':>4}  {'state':<10}{'variant':<17}{'p50 µs':>9}{'p99 µs':>9}"
        f"{'python/it':>11}"
    )
    for name in BUILTIN_MODELS:
        robot = load_robot_model(name)
        solver = compiled(robot)
        for state, (terms, desired) in states(robot).items():
            times = measure(robot, solver, terms, desired, args.calls, args.chunks)
            python50 = float(np.percentile(times["python daqp"], 50))
            for label, samples in times.items():
                p50, p99 = np.percentile(samples, [50, 99])
                print(
                    f"{name:<19}{robot.model.nv:>4}  {state:<10}{label:<17}{p50 * 1e6:>9.1f}"
                    f"{p99 * 1e6:>9.1f}{python50 / p50:>10.2f}x"
                )


def measure(
    robot: RobotModel, solver, terms: DynamicsTerms, desired: np.ndarray, calls: int, chunks: int
) -> dict[str, list[float]]:
    """Each variant's seconds per call on one request, in alternating chunks."""
    mus = [c.friction_coefficient for c in robot.contacts]
    limit = robot.torque_limit
    request = (terms, desired, BOTH_FEET, mus)
    variants = {
        "python daqp": lambda _: solve_inverse_dynamics(*request, limit, qp_solver="daqp"),
        "python quadprog": lambda _: solve_inverse_dynamics(*request, limit, qp_solver="quadprog"),
        "compiled": lambda _: solver.solve(*request),
    }
    for step in variants.values():
        timed(step, range(WARMUP_CALLS))
    solver.time_solve(*request, repeats=WARMUP_CALLS)
    times: dict[str, list[float]] = {label: [] for label in [*variants, "C++ alone"]}
    per_chunk = max(1, calls // chunks)
    for _ in range(chunks):
        for label, step in variants.items():
            times[label] += timed(step, range(per_chunk))
        times["C++ alone"] += solver.time_solve(*request, repeats=per_chunk).tolist()
    return times


if __name__ == "__main__":
    main()
