"""The compiled inverse dynamics against its specification, ``solve_inverse_dynamics`` (Python).

Per built-in model, on 1,080 seeded states (``tests/controller_server/states.py``) whose
terms come from ``compute_dynamics_terms``, the C++ (``_core.InverseDynamics``, eiquadprog)
and the Python with ``qp_solver="quadprog"`` (the same method: Goldfarb–Idnani's dual active
set) run on the same terms, and take the same branch on every state:

* standing near the standing pose with small accelerations: mostly the exact case (no QP);
  measured ground wrenches on the spread-out states of the terms' test: torques, forces,
  wrenches and accelerations within 1e-8 of the Python's, relative to their scale;
* accelerations that push the centre of pressure off the feet, torque limits scaled down
  (saturation), single support and no support: the QP cases, where both answers must be
  feasible to rounding (root balance, friction pyramids, torque limits, within
  ``QP_FEASIBILITY`` of the forces' scale), agree within ``QP_TOLERANCE`` and have the same
  cost to ``QP_TOLERANCE``; their largest relative differences are printed (``-s``).

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
QP_FEASIBILITY = 1e-9  # relative to the forces' scale (the robot's weight, at least 1 N)
QP_TOLERANCE = 1e-8  # relative to the scale, as EXACT_TOLERANCE: 2.1e-9 at most seen
SCALED_QP_TOLERANCE = 1e-3
"""The fast joints' QPs (data ~1e10, solved scaled down by ~1e4): torques agree to 1.4e-7, but
on one dino_biped state of 30 eiquadprog stops 3.3e-6 (relative) above the optimum on which
quadprog and DAQP agree to 1e-12, with forces 5.7e-4 and q̈ 1.1e-4 apart (relative): its
dependence test (|d| ≤ ε ‖R‖) excludes a torque row that quadprog adds."""
SCALED_COST_TOLERANCE = 1e-5
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
        """The result, its branch, and how many of its QP solves gave no answer."""
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


def infeasibility(robot, supports, torque_limit, result, label: str) -> float:
    """The largest violation of root balance (but on the no-answer path) and of the friction
    pyramids, in N and N·m; torques within their limits and zero force off the supports are
    asserted exactly."""
    assert np.all(np.abs(result["joint_torque"]) <= torque_limit), label
    off = ~np.repeat(np.asarray(supports, dtype=bool), counts(robot))
    assert np.all(np.asarray(result["contact_force_in_world"])[off] == 0.0), label
    mus = np.repeat(frictions(robot), counts(robot)) / math.sqrt(2.0)
    fx, fy, fz = np.asarray(result["contact_force_in_world"]).T
    violations = [-fz, np.abs(fx) - mus * fz, np.abs(fy) - mus * fz]
    if label.endswith("least_squares"):  # no QP answer: the root is not balanced, by design
        assert np.isfinite(result["root_wrench_residual"]), label
    else:
        violations.append(np.array([result["root_wrench_residual"]]))
    return max(0.0, float(np.max(np.concatenate(violations))))


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
    worst_cost = worst_scaled_cost = 0.0  # |ΔJ| / max(1, |J|), unscaled and scaled data
    worst_violation = 0.0  # infeasibility / force scale
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
                measured_wrenches=measured, qp_solver="quadprog",
            )  # fmt: skip
            paths[(case.name, got["path"])] += 1
            if got["path"] != python_path:
                mismatched.append((case.name, got["path"], python_path))
                continue
            assert got["qp_failures"] == python_failures, (case.name, got, python_failures)
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
            # Feasible to rounding, relative to the forces' scale: the weight, or the data's
            # (_solve_qp scaled them down by k).
            force_scale = max(1.0, terms.total_mass * 9.81) * k
            for label, answer in (("compiled", got), ("python", as_dict(want))):
                label = f"{case.name}: {label} {got['path']}"
                violation = infeasibility(robot, supports, torque_limit, answer, label)
                worst_violation = max(worst_violation, violation / force_scale)
            if k == 1.0:  # scaled data (~1e10): torques at their limits differ by > 1e-6
                assert got["saturated_joints"] == want.saturated_joints, case.name
            if got["path"] == "least_squares":
                costs = [
                    least_squares_cost(
                        terms, desired, supports, supported_forces(robot, supports, f)
                    )
                    for f in (got["contact_force_in_world"], want.contact_force_in_world)
                ]
            else:
                costs = [
                    nearest_motion_cost(
                        terms, desired, supports, a, supported_forces(robot, supports, f)
                    )
                    for a, f in (
                        (got["acceleration"], got["contact_force_in_world"]),
                        (want.acceleration, want.contact_force_in_world),
                    )
                ]
            relative_cost = abs(costs[0] - costs[1]) / max(1.0, abs(costs[1]))
            if k == 1.0:
                worst_cost = max(worst_cost, relative_cost)
            else:
                worst_scaled_cost = max(worst_scaled_cost, relative_cost)
    count = sum(case.count for case in CASES)
    print(
        f"\n{model.name}: {count} states; paths {dict(sorted(paths.items()))}"
        f"\n  exact/measured: worst relative difference {worst_exact}"
        f"\n  QP cases: worst relative difference {worst_qp}"
        f"\n  QP cases with scaled data: worst relative difference {worst_scaled}"
        f"\n  QP cases: worst |ΔJ|/max(1, |J|) {worst_cost:.1e} (scaled data"
        f" {worst_scaled_cost:.1e}); worst infeasibility / force scale {worst_violation:.1e}"
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
    # One method (Goldfarb–Idnani) in both kernels: the same branch on every state, answers
    # feasible to rounding and equal to rounding (the optimum of a strictly convex QP is
    # unique, and both find it exactly on the same active set).
    assert not mismatched, mismatched
    assert worst_violation <= QP_FEASIBILITY, worst_violation
    assert max(worst_qp.values()) <= QP_TOLERANCE, worst_qp
    assert worst_cost <= QP_TOLERANCE, worst_cost
    assert max(worst_scaled.values()) <= SCALED_QP_TOLERANCE, worst_scaled
    assert worst_scaled_cost <= SCALED_COST_TOLERANCE, worst_scaled_cost


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


def test_a_repeated_solve_calls_malloc_not_once(tmp_path):
    """Counted, not assumed: with a malloc that counts its calls preloaded, 20 more solves
    on a warm object (each support combination and path seen once) add no call, on every
    path: eiquadprog's solver is sized once per QP (``reset``) and its solve writes into
    that workspace."""
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
    # durations may cost.
    assert all(-1 <= count <= 1 for count in extra.values()), extra
