"""The compiled inverse dynamics against its specification, ``solve_inverse_dynamics`` (Python).

Per built-in model, on 1,080 seeded states (``tests/controller_server/states.py``) whose
terms come from ``compute_dynamics_terms``, the C++ (``_core.InverseDynamics``) and the
Python with ``qp_solver="proxqp"`` (the same solver, the same settings) run on the same
terms:

* standing near the standing pose with small accelerations: mostly the exact case (no QP);
  measured ground wrenches on the spread-out states of the terms' test: torques, forces,
  wrenches and accelerations within 1e-8 of the Python's, relative to their scale;
* accelerations that push the centre of pressure off the feet, torque limits scaled down
  (saturation), single support and no support: the QP cases, where both answers must be
  feasible (root balance, friction pyramids, torque limits, to ProxQP's ``eps_abs``) and
  of equal cost within the bound that tolerance gives; their largest relative difference
  is printed (``-s``).

Also: a repeated tick allocates nothing new; NaN and infinite inputs are a ValueError,
never a crash; bad sizes are a ValueError.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil
import subprocess
import sys
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from controller_server import inverse_dynamics
from controller_server.compiled import load_core
from controller_server.dynamics import DynamicsTerms, compute_dynamics_terms
from controller_server.inverse_dynamics import (
    QP_DATA_SCALE,
    InverseDynamicsResult,
    solve_inverse_dynamics,
)
from controller_server.models import BUILTIN_MODELS, RobotModel, load_robot_model
from controller_server.solvers.qp import solve_qp_bounded
from tests.controller_server.states import random_states

MODEL_NAMES = tuple(BUILTIN_MODELS)
EXACT_TOLERANCE = 1e-8  # relative to the scale (max |τ| or max |f|, at least 1)
QP_EPS_ABS = 1e-5  # ProxQP's default stopping tolerance, which both paths keep
FIELDS = ("joint_torque", "contact_force_in_world", "contact_wrench_in_world", "acceleration")
FORCE_REGULARIZATION = 1e-4  # solve_inverse_dynamics' defaults
SUPPORT_WEIGHT = 100.0
WEAK_TORQUE_SCALE = 0.2  # torque limits scaled down for the saturated cases


@dataclass(frozen=True)
class Case:
    """One family of seeded states, and what it should exercise."""

    name: str
    count: int
    configuration_spread: float  # rad (and m) of the step from standing
    velocity_spread: float  # rad/s
    acceleration_spread: float  # rad/s² of the requested q̈
    supports: tuple[bool, ...] | None  # None: drawn per state
    weak: bool = False  # torque limits × WEAK_TORQUE_SCALE
    measured: bool = False


CASES = (
    Case("standing", 400, 0.01, 0.1, 0.1, (True, True)),
    Case("cop off the feet", 250, 0.05, 0.5, 10.0, (True, True)),
    Case("saturated", 150, 0.05, 0.5, 3.0, (True, True), weak=True),
    Case("single support", 100, 0.05, 0.5, 3.0, None),
    Case("no support", 50, 0.05, 0.5, 1.0, (False, False)),
    # Velocities of ~1e3 rad/s make QP data beyond QP_DATA_SCALE: solved scaled down.
    Case("fast joints", 30, 0.05, 1000.0, 3.0, (True, True)),
    Case("measured", 100, math.nan, math.nan, 5.0, None, measured=True),
)


@pytest.fixture(scope="module", params=MODEL_NAMES)
def robot(request) -> RobotModel:
    return load_robot_model(request.param)


def counts(robot: RobotModel) -> list[int]:
    return [len(contact.points_in_frame) for contact in robot.contacts]


def frictions(robot: RobotModel) -> list[float]:
    return [contact.friction_coefficient for contact in robot.contacts]


def compiled_solver(robot: RobotModel, torque_limit: np.ndarray | None = None):
    limit = robot.torque_limit if torque_limit is None else torque_limit
    return load_core().InverseDynamics(robot.model.nv, counts(robot), limit)


class PythonPath:
    """Which branch ``solve_inverse_dynamics`` took: its QP functions, wrapped to record."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch):
        self.path, self.condensed_motion, self.failures = "exact", None, 0
        nearest, condensed = (
            inverse_dynamics.nearest_feasible_motion,
            inverse_dynamics._condensed_motion,
        )

        def record_nearest(*args, **kwargs):
            answer = nearest(*args, **kwargs)
            if answer is None:
                self.path = "least_squares"
            elif self.path != "condensed_qp" or answer[0] is not self.condensed_motion:
                self.path = "full_qp"
            return answer

        def record_condensed(*args, **kwargs):
            answer = condensed(*args, **kwargs)
            self.path = "condensed_qp" if answer is not None else "full_qp"
            self.condensed_motion = None if answer is None else answer[0]
            return answer

        def record_solve(*args, **kwargs):
            solution = solve_qp_bounded(*args, **kwargs)
            self.failures += not solution.found
            return solution

        solve_qp = inverse_dynamics._solve_qp
        self.scaled_solves, self.data_scale = 0, 1.0

        def record_scaling(P, q, G, h, *, A=None, b=None, **kwargs):
            linear = np.concatenate([q, h] if b is None else [q, h, b])
            k = max(1.0, float(np.max(np.abs(linear), initial=0.0)) / QP_DATA_SCALE)
            self.scaled_solves += k > 1.0
            self.data_scale = max(self.data_scale, k)
            return solve_qp(P, q, G, h, A=A, b=b, **kwargs)

        monkeypatch.setattr(inverse_dynamics, "_solve_qp", record_scaling)
        monkeypatch.setattr(inverse_dynamics, "nearest_feasible_motion", record_nearest)
        monkeypatch.setattr(inverse_dynamics, "_condensed_motion", record_condensed)
        monkeypatch.setattr(inverse_dynamics, "solve_qp_bounded", record_solve)

    def solve(self, *args, **kwargs) -> tuple[InverseDynamicsResult, str, int]:
        """The result, its branch, and how many of its ProxQP solves gave no answer."""
        self.path, self.condensed_motion, self.failures = "exact", None, 0
        self.data_scale = 1.0
        result = solve_inverse_dynamics(*args, **kwargs)
        measured = kwargs.get("measured_wrenches") is not None
        return result, ("measured" if measured else self.path), self.failures


def relative_differences(got: dict, want: InverseDynamicsResult) -> dict[str, float]:
    """Per field, max |C++ − Python| over the field's scale (max |Python|, at least 1)."""
    differences = {}
    for field in FIELDS:
        expected = getattr(want, field)
        scale = max(1.0, float(np.max(np.abs(expected), initial=0.0)))
        error = float(np.max(np.abs(got[field] - expected), initial=0.0))
        differences[field] = error / scale
    return differences


def nearest_motion_cost(terms: DynamicsTerms, desired, supports, acceleration, forces) -> float:
    """nearest_feasible_motion's objective at (q̈, f): ½‖q̈ − q̈_des‖²_M + ½ w_s ‖J_sup q̈ +
    J̇_sup q̇‖² + ½ ε ‖f‖² (its full QP; the condensed one has the same minimizer)."""
    weight = SUPPORT_WEIGHT * terms.total_mass
    step = acceleration - desired
    cost = 0.5 * step @ terms.mass_matrix @ step + 0.5 * FORCE_REGULARIZATION * np.sum(forces**2)
    for jacobian, drift, on in zip(
        terms.support_jacobians, terms.support_drifts, supports, strict=True
    ):
        if on:
            cost += 0.5 * weight * np.sum((jacobian @ acceleration + drift) ** 2)
    return float(cost)


def least_squares_cost(terms: DynamicsTerms, desired, supports, forces) -> float:
    """_least_squares_balance's objective: ½‖G f − w‖² + ½ ε ‖f‖² over the supports' points."""
    rows = [J for J, on in zip(terms.point_jacobians, supports, strict=True) if on]
    if not rows:
        return 0.0
    G = np.vstack(rows)[:, :6].T
    wrench = (terms.mass_matrix @ desired + terms.bias_forces)[:6]
    force = forces.reshape(-1)
    return float(
        0.5 * np.sum((G @ force - wrench) ** 2) + 0.5 * FORCE_REGULARIZATION * force @ force
    )


def supported_forces(robot: RobotModel, supports, forces: np.ndarray) -> np.ndarray:
    mask = np.repeat(np.asarray(supports, dtype=bool), counts(robot))
    return forces[mask]


def assert_feasible(robot, supports, torque_limit, result, tolerance: float, label: str):
    """Root balance (but on the no-answer path), friction pyramids, torque limits, zero force
    off the supports."""
    if label.endswith("least_squares"):  # no QP answer: the root is not balanced, by design
        assert np.isfinite(result["root_wrench_residual"]), label
    else:
        assert result["root_wrench_residual"] <= tolerance, (label, result["root_wrench_residual"])
    assert np.all(np.abs(result["joint_torque"]) <= torque_limit), label
    mus = np.repeat(frictions(robot), counts(robot)) / math.sqrt(2.0)
    fx, fy, fz = np.asarray(result["contact_force_in_world"]).T
    assert np.all(fz >= -tolerance), (label, fz)
    assert np.all(np.abs(fx) <= mus * fz + tolerance), (label, fx, fz)
    assert np.all(np.abs(fy) <= mus * fz + tolerance), (label, fy, fz)
    off = ~np.repeat(np.asarray(supports, dtype=bool), counts(robot))
    assert np.all(np.asarray(result["contact_force_in_world"])[off] == 0.0), label


def as_dict(result: InverseDynamicsResult) -> dict:
    return {
        "joint_torque": result.joint_torque,
        "contact_force_in_world": result.contact_force_in_world,
        "contact_wrench_in_world": result.contact_wrench_in_world,
        "acceleration": result.acceleration,
        "root_wrench_residual": result.root_wrench_residual,
        "saturated_joints": result.saturated_joints,
    }


def case_states(robot: RobotModel, case: Case, seed: int):
    """The case's ``(q, v)``: near standing, or (measured) the terms' test's spread."""
    if case.measured:
        return random_states(robot, case.count, seed)
    return random_states(
        robot, case.count, seed, (case.configuration_spread,), (case.velocity_spread,)
    )


def test_the_compiled_inverse_dynamics_matches_the_python_on_1080_states(robot, monkeypatch):
    model = robot.model
    data = model.createData()
    python = PythonPath(monkeypatch)
    limits = {False: robot.torque_limit, True: robot.torque_limit * WEAK_TORQUE_SCALE}
    solvers = {weak: compiled_solver(robot, limit) for weak, limit in limits.items()}
    mus = frictions(robot)
    worst_exact: dict[str, float] = {}  # exact and measured cases, per field
    worst_qp: dict[str, float] = {}  # the QP cases, per field
    worst_scaled: dict[str, float] = {}  # those whose QP data were scaled down
    worst_cost = 0.0  # |ΔJ| / bound
    paths: Counter[tuple[str, str]] = Counter()
    mismatched: list[tuple[str, str, str]] = []
    for index, case in enumerate(CASES):
        rng = np.random.default_rng(1000 + index)
        for q, v in case_states(robot, case, seed=index):
            terms = compute_dynamics_terms(robot, data, q, v)
            desired = rng.normal(scale=case.acceleration_spread, size=model.nv)
            supports = case.supports
            if supports is None:
                supports = ((True, False), (False, True))[int(rng.integers(2))]
            measured = rng.normal(scale=200.0, size=(2, 6)) if case.measured else None
            torque_limit = limits[case.weak]
            got = solvers[case.weak].solve(
                terms, desired, supports, mus, measured_wrenches=measured
            )
            want, python_path, python_failures = python.solve(
                terms, desired, supports, mus, torque_limit,
                measured_wrenches=measured, qp_solver="proxqp",
            )  # fmt: skip
            paths[(case.name, got["path"])] += 1
            if got["path"] != python_path:
                # Only where a ProxQP solve gave no answer (at its iteration cap, or declaring a
                # feasible QP infeasible) and its twin, on data that differ by rounding, did.
                assert got["qp_failures"] != python_failures, (case.name, got, python_path)
                mismatched.append((case.name, got["path"], python_path))
                continue
            differences = relative_differences(got, want)
            if got["path"] in ("exact", "measured"):
                for field, difference in differences.items():
                    worst_exact[field] = max(worst_exact.get(field, 0.0), difference)
                assert got["saturated_joints"] == want.saturated_joints
                assert got["root_wrench_residual"] == pytest.approx(
                    want.root_wrench_residual, rel=1e-8, abs=1e-8
                )
                continue
            k = python.data_scale
            worst = worst_qp if k == 1.0 else worst_scaled
            for field, difference in differences.items():
                worst[field] = max(worst.get(field, 0.0), difference)
            # ProxQP's residuals are within eps_abs on the problem it solves, which _solve_qp
            # scaled down by k: on ours, within eps_abs k (×10 for the 2-norm of 6 rows).
            tolerance = 10.0 * QP_EPS_ABS * k
            for label, answer in (("compiled", got), ("python", as_dict(want))):
                label = f"{case.name}: {label} {got['path']}"
                assert_feasible(robot, supports, torque_limit, answer, tolerance, label)
            if got["path"] == "least_squares":
                costs = [
                    least_squares_cost(
                        terms, desired, supports, supported_forces(robot, supports, f)
                    )
                    for f in (got["contact_force_in_world"], want.contact_force_in_world)
                ]
            else:
                if k == 1.0:  # torque rows within eps_abs: no clipping beyond 1e-6 seen here
                    assert got["saturated_joints"] == 0 and want.saturated_joints == 0
                costs = [
                    nearest_motion_cost(
                        terms, desired, supports, a, supported_forces(robot, supports, f)
                    )
                    for a, f in (
                        (got["acceleration"], got["contact_force_in_world"]),
                        (want.acceleration, want.contact_force_in_world),
                    )
                ]
            # ProxQP stops at primal and dual residuals ≤ eps_abs: two such answers of one
            # convex QP differ in cost by about eps_abs times the size of the cost's gradient
            # and multipliers, which we bound by eps_abs (1 + |J|).
            bound = QP_EPS_ABS * (1.0 + abs(costs[1]))
            assert abs(costs[0] - costs[1]) <= bound, (case.name, costs)
            worst_cost = max(worst_cost, abs(costs[0] - costs[1]) / bound)
    count = sum(case.count for case in CASES)
    print(
        f"\n{model.name}: {count} states; paths {dict(sorted(paths.items()))}"
        f"\n  exact/measured: worst relative difference {worst_exact}"
        f"\n  QP cases: worst relative difference {worst_qp}"
        f"\n  QP cases with scaled data: worst relative difference {worst_scaled}"
        f"\n  QP cases: worst |ΔJ|/bound {worst_cost:.1e}"
        f"\n  path mismatches (case, compiled, python): {mismatched}"
    )
    assert count >= 1000
    assert max(worst_exact.values()) <= EXACT_TOLERANCE, worst_exact
    # Each family reached what it is for.
    assert paths[("standing", "exact")] >= 0.5 * CASES[0].count, paths
    assert paths[("measured", "measured")] == CASES[-1].count
    for name in ("cop off the feet", "saturated", "single support", "no support"):
        assert sum(n for (case, path), n in paths.items() if case == name and path != "exact") > 0
    assert any(path == "full_qp" for _, path in paths), paths
    assert python.scaled_solves > 0  # the fast joints' QPs were solved scaled down
    # The same algorithm and solver settings: the same branch, but for a few states where one
    # of the two ProxQP solves gave no answer (1.2 % at most here; ProxQP on Python is this
    # machine's AVX-512 build, ours is baseline x86-64, which changes rounding).
    assert len(mismatched) <= 0.02 * count, mismatched


def test_a_repeated_tick_allocates_nothing_new(robot):
    """Workspaces are made per support combination on its first solve, never again."""
    model = robot.model
    solver = compiled_solver(robot, robot.torque_limit * WEAK_TORQUE_SCALE)

    def sizes():
        return solver.support_set_count, solver.qp_cache_size, solver.workspace_allocations

    assert sizes() == (0, 0, 0)
    states = random_states(robot, 20, seed=7, configuration_spreads=(0.05,))
    rng = np.random.default_rng(7)
    requests = [
        (
            compute_dynamics_terms(robot, model.createData(), q, v),
            rng.normal(scale=5.0, size=model.nv),
        )
        for q, v in states
    ]
    flag_sets = ((True, True), (True, False), (False, True), (False, False))
    seen = Counter()
    for flags in flag_sets:
        for terms, desired in requests:
            seen[solver.solve(terms, desired, flags, frictions(robot))["path"]] += 1
    first = sizes()
    assert first[0] == len(flag_sets) and first[1] > 0, first
    assert seen["full_qp"] > 0 and seen["condensed_qp"] > 0, seen
    for _ in range(2):
        for flags in flag_sets:
            for terms, desired in requests:
                solver.solve(terms, desired, flags, frictions(robot))
    assert sizes() == first


def test_the_results_are_fresh_arrays(robot):
    solver = compiled_solver(robot)
    model = robot.model
    (q0, v0), (q1, v1) = random_states(robot, 2, seed=3, configuration_spreads=(0.01,))
    data = model.createData()
    first = solver.solve(
        compute_dynamics_terms(robot, data, q0, v0),
        np.zeros(model.nv),
        (True, True),
        frictions(robot),
    )
    kept = {field: first[field].copy() for field in FIELDS}
    second = solver.solve(
        compute_dynamics_terms(robot, data, q1, v1),
        np.ones(model.nv),
        (True, False),
        frictions(robot),
    )
    for field in FIELDS:
        np.testing.assert_array_equal(first[field], kept[field])
        assert not np.shares_memory(first[field], second[field])
        assert first[field].flags.writeable and first[field].dtype == np.float64


def corrupt(terms: DynamicsTerms, **changes) -> DynamicsTerms:
    return dataclasses.replace(terms, **changes)


def test_non_finite_inputs_are_a_value_error_never_a_crash(robot):
    model = robot.model
    solver = compiled_solver(robot)
    q, v = random_states(robot, 1)[0]
    terms = compute_dynamics_terms(robot, model.createData(), q, v)
    mus = frictions(robot)
    desired = np.zeros(model.nv)
    reference = solver.solve(terms, desired, (True, True), mus)
    bad_mass = terms.mass_matrix.copy()
    bad_mass[3, 4] = np.inf
    bad_jacobian = terms.point_jacobians[0].copy()
    bad_jacobian[0, 0] = np.nan
    both, neither = (True, True), (False, False)
    bad_point_jacobians = (bad_jacobian, *terms.point_jacobians[1:])
    bad_bias = corrupt(terms, bias_forces=np.full(model.nv, np.inf))
    nan_wrenches = np.full((2, 6), np.nan)
    for message, arguments, keywords in (
        ("acceleration", (terms, np.full(model.nv, np.nan), both, mus), {}),
        ("mass_matrix", (corrupt(terms, mass_matrix=bad_mass), desired, both, mus), {}),
        ("bias_forces", (bad_bias, desired, neither, mus), {}),
        ("Jacobian", (corrupt(terms, point_jacobians=bad_point_jacobians), desired, both, mus), {}),
        ("friction", (terms, desired, both, [np.nan, 0.8]), {}),
        ("support_weight", (terms, desired, both, mus), {"support_weight": np.inf}),
        ("measured_wrenches", (terms, desired, both, mus), {"measured_wrenches": nan_wrenches}),
    ):  # fmt: skip
        with pytest.raises(ValueError, match=message):
            solver.solve(*arguments, **keywords)
    # The object is unharmed: the same answer as before.
    again = solver.solve(terms, desired, (True, True), mus)
    for field in FIELDS:
        np.testing.assert_array_equal(again[field], reference[field])


def test_a_mass_matrix_that_is_not_positive_definite_is_a_linalg_error_as_in_python(robot):
    model = robot.model
    q, v = random_states(robot, 1)[0]
    terms = compute_dynamics_terms(robot, model.createData(), q, v)
    flipped = corrupt(terms, mass_matrix=-terms.mass_matrix)
    wrenches = np.zeros((2, 6))
    args = (flipped, np.zeros(model.nv), (True, True), frictions(robot))
    with pytest.raises(np.linalg.LinAlgError):
        solve_inverse_dynamics(*args, robot.torque_limit, measured_wrenches=wrenches)
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        compiled_solver(robot).solve(*args, measured_wrenches=wrenches)


def test_bad_sizes_are_a_value_error(robot):
    model = robot.model
    core = load_core()
    with pytest.raises(ValueError, match="torque_limit"):
        core.InverseDynamics(model.nv, counts(robot), robot.torque_limit[:-1])
    with pytest.raises(ValueError, match="torque_limit"):
        core.InverseDynamics(model.nv, counts(robot), -robot.torque_limit)
    solver = compiled_solver(robot)
    terms = compute_dynamics_terms(robot, model.createData(), *random_states(robot, 1)[0])
    with pytest.raises(ValueError, match="expected nv"):
        solver.solve(terms, np.zeros(model.nv - 1), (True, True), frictions(robot))
    with pytest.raises(ValueError, match="expected nv"):
        solver.solve(terms, np.zeros(model.nv), (True,), frictions(robot))
    narrow = (terms.support_jacobians[0][:, :-1], *terms.support_jacobians[1:])
    with pytest.raises(ValueError, match="sizes differ"):
        solver.solve(
            corrupt(terms, support_jacobians=narrow),
            np.zeros(model.nv),
            (True, True),
            frictions(robot),
        )
    with pytest.raises(ValueError, match="expected nv"):
        solver.solve(
            terms, np.zeros(model.nv), (True, True), frictions(robot), measured_wrenches=np.zeros(6)
        )


# A repeated tick makes no heap allocation: malloc counted by a preloaded shim ---------------

COUNTING_MALLOC = r"""
#include <stddef.h>
extern void* __libc_malloc(size_t);
extern void* __libc_calloc(size_t, size_t);
extern void* __libc_realloc(void*, size_t);
extern void* __libc_memalign(size_t, size_t);
static size_t calls;
size_t poise_malloc_calls(void) { return __atomic_load_n(&calls, __ATOMIC_RELAXED); }
#define COUNT() __atomic_add_fetch(&calls, 1, __ATOMIC_RELAXED)
void* malloc(size_t n) { COUNT(); return __libc_malloc(n); }
void* calloc(size_t n, size_t m) { COUNT(); return __libc_calloc(n, m); }
void* realloc(void* p, size_t n) { COUNT(); return __libc_realloc(p, n); }
void* memalign(size_t a, size_t n) { COUNT(); return __libc_memalign(a, n); }
void* aligned_alloc(size_t a, size_t n) { COUNT(); return __libc_memalign(a, n); }
int posix_memalign(void** p, size_t a, size_t n) {
  COUNT();
  *p = __libc_memalign(a, n);
  return *p ? 0 : 12;
}
"""

# time_solve(repeats=n) converts its inputs, runs n solves without the GIL and returns n
# durations: 20 more solves that allocated would add at least 20 calls to malloc.
COUNTING_SCRIPT = r"""
import ctypes, json
import numpy as np
from controller_server.compiled import load_core
from controller_server.dynamics import compute_dynamics_terms
from controller_server.models import BUILTIN_MODELS, load_robot_model
from tests.controller_server.states import random_states

calls = ctypes.CDLL(None).poise_malloc_calls
calls.restype = ctypes.c_size_t
extra = {}
for name in BUILTIN_MODELS:
    robot = load_robot_model(name)
    model = robot.model
    counts = [len(c.points_in_frame) for c in robot.contacts]
    mus = [c.friction_coefficient for c in robot.contacts]
    solver = load_core().InverseDynamics(model.nv, counts, robot.torque_limit * 0.2)
    rng = np.random.default_rng(5)
    for index, (q, v) in enumerate(random_states(robot, 6, 5, (0.05,), (0.5,))):
        terms = compute_dynamics_terms(robot, model.createData(), q, v)
        desired = rng.normal(scale=(0.0, 10.0)[index % 2], size=model.nv)
        for flags in ((True, True), (True, False), (False, False), "measured"):
            wrenches = np.full((2, 6), 50.0) if flags == "measured" else None
            request = (terms, desired, (True, True) if wrenches is not None else flags, mus)
            path = solver.solve(*request, measured_wrenches=wrenches)["path"]
            solver.time_solve(*request, measured_wrenches=wrenches, repeats=21)
            before = calls()
            solver.time_solve(*request, measured_wrenches=wrenches, repeats=21)
            middle = calls()
            solver.time_solve(*request, measured_wrenches=wrenches, repeats=41)
            key = f"{name} {index} {flags} {path}"
            extra[key] = (calls() - middle) - (middle - before)
print(json.dumps(extra))
"""


def test_a_repeated_solve_calls_malloc_not_once_but_inside_proxqp(tmp_path):
    """Counted, not assumed: with a malloc that counts its calls preloaded, 20 more solves
    on a warm object (each support combination and path seen once) add no call on the
    exact and measured paths. On the QP paths ProxQP itself may: its LDLᵀ update when one
    constraint enters the active set (``ldlt_insert_rows_and_cols``) takes Eigen's GEMV
    fallback for a one-column product, which copies that column into a heap temporary
    (8 (dim + n_eq) bytes; once per solve on one of the 24 full-QP states here)."""
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        pytest.skip("no C compiler to build the counting malloc")
    library = tmp_path / "libcounting_malloc.so"
    source = tmp_path / "counting_malloc.c"
    source.write_text(COUNTING_MALLOC)
    subprocess.run(
        [compiler, "-O2", "-shared", "-fPIC", "-o", str(library), str(source)], check=True
    )
    root = Path(__file__).resolve().parents[2]
    result = subprocess.run(
        [sys.executable, "-c", COUNTING_SCRIPT],
        capture_output=True,
        text=True,
        cwd=root,
        env={**os.environ, "LD_PRELOAD": str(library)},
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    extra = json.loads(result.stdout)
    paths = {key.rsplit(" ", 1)[1] for key in extra}
    assert {"exact", "measured", "condensed_qp", "full_qp"} <= paths, paths
    # 20 more solves: no more malloc calls, but for one that the larger array of
    # durations may cost; on the QP paths, at most ProxQP's one per solve.
    exact = {key: n for key, n in extra.items() if key.endswith(("exact", "measured"))}
    assert all(-1 <= count <= 1 for count in exact.values()), exact
    assert all(-1 <= count <= 21 for count in extra.values()), extra
    in_proxqp = sorted(key for key, count in extra.items() if count > 1)
    print(f"\nsolves that allocate (inside ProxQP): {in_proxqp} of {len(extra)}")
    assert len(in_proxqp) <= 0.1 * len(extra), in_proxqp
