"""Damped least squares (Maciejewski 1990) in the KKT solve, through a kinematic singularity."""

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller_server.constraints import Equality
from controller_server.features import Objective
from controller_server.math.damped import damped_solve_psd, damping_for_gain_bound
from controller_server.solvers import build_weighted_problem, solve_weighted_kkt


@settings(max_examples=300, deadline=None)
@given(st.floats(1e-6, 1e3), st.floats(1e-3, 1e6))
def test_gain_never_exceeds_the_bound(sigma_min, bound):
    """σ / (σ² + λ²) ≤ B for every σ ≥ σ_min (eq. 16–18)."""
    damping = damping_for_gain_bound(sigma_min, bound)
    sigmas = sigma_min * np.geomspace(1.0, 1e6, 400)
    assert np.all(sigmas / (sigmas**2 + damping**2) <= bound * (1 + 1e-9))
    if sigma_min >= 1.0 / bound:
        assert damping == 0.0


def test_damping_is_continuous_in_the_smallest_singular_value():
    bound = 50.0
    sigmas = np.linspace(0.0, 3.0 / bound, 30001)
    dampings = np.array([damping_for_gain_bound(s, bound) for s in sigmas])
    # λ² is Lipschitz in σ_min (slope ≤ 3/B), so |Δλ| ≤ √(3 Δσ / B): no jumps.
    step = sigmas[1] - sigmas[0]
    assert np.max(np.abs(np.diff(dampings))) <= np.sqrt(3 * step / bound)
    assert dampings[0] == pytest.approx(0.5 / bound)
    assert dampings[-1] == 0.0


def test_damped_solve_matches_the_svd_formula():
    rng = np.random.default_rng(0)
    K = rng.normal(size=(4, 7))
    K[3] = K[2] * (1 + 1e-7)  # nearly dependent rows: a tiny singular value
    rhs = rng.normal(size=4)
    y, damping, condition = damped_solve_psd(K @ K.T, rhs, gain_bound=20.0)
    U, sigma, _ = np.linalg.svd(K)
    assert damping > 0
    expected = U @ ((U.T @ rhs) / (sigma**2 + damping**2))
    np.testing.assert_allclose(y, expected, rtol=1e-9, atol=1e-12)
    assert np.linalg.norm(K.T @ y) <= 20.0 * np.linalg.norm(rhs) * (1 + 1e-9)
    assert condition > 1e10


def planar_arm() -> pin.Model:
    """Two 0.5 m links with pitch joints: straight at θ₂ = 0, a kinematic singularity."""
    model = pin.Model()
    inertia = pin.Inertia(1.0, np.array([0.0, 0.0, -0.25]), np.diag([0.02, 0.02, 0.001]))
    shoulder = model.addJoint(0, pin.JointModelRY(), pin.SE3.Identity(), "shoulder")
    model.appendBodyToJoint(shoulder, inertia, pin.SE3.Identity())
    placement = pin.SE3(np.eye(3), np.array([0.0, 0.0, -0.5]))
    elbow = model.addJoint(shoulder, pin.JointModelRY(), placement, "elbow")
    model.appendBodyToJoint(elbow, inertia, pin.SE3.Identity())
    model.addFrame(pin.Frame("hand", elbow, 0, placement, pin.FrameType.OP_FRAME))
    return model


def hand_rows(model, data, q, v):
    """x–z acceleration rows of the hand: J q̈ = a_des − J̇ q̇."""
    pin.computeJointJacobians(model, data, q)
    pin.forwardKinematics(model, data, q, v, np.zeros(2))
    pin.updateFramePlacements(model, data)
    frame = model.getFrameId("hand")
    jacobian = pin.getFrameJacobian(model, data, frame, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
    drift = pin.getFrameClassicalAcceleration(
        model, data, frame, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    )
    rows = [0, 2]
    desired = np.array([0.0, 2.0])  # pull the hand along the arm: unreachable when straight
    return Equality(jacobian[rows], desired - drift.linear[rows])


def solve_along_path(bound, elbow_angles):
    model = planar_arm()
    data = model.createData()
    velocity = np.array([0.4, -0.8])
    objective = Objective("tracking", np.eye(2), np.zeros(2), np.full(2, 1e-2))
    results = []
    for angle in elbow_angles:
        equality = hand_rows(model, data, np.array([0.3, angle]), velocity)
        problem = build_weighted_problem([objective], equality, 500.0, bound)
        results.append((problem, solve_weighted_kkt(problem)))
    return results


def test_path_through_a_singularity_stays_bounded_and_continuous():
    elbow_angles = np.linspace(-0.2, 0.2, 401)  # passes through θ₂ = 0 exactly
    bound = 3.0
    damped = solve_along_path(bound, elbow_angles)
    undamped = solve_along_path(1e14, elbow_angles)

    damped_norms = np.array([np.linalg.norm(s.x) for _, s in damped])
    undamped_norms = np.array([np.linalg.norm(s.x) for _, s in undamped])
    for problem, solution in damped:
        # Maciejewski eq. 18 in the metric of M: ‖x − x_free‖_M ≤ B ‖d − C x_free‖.
        M = problem.hessian + solution.objective_damping**2 * np.eye(2)
        step = solution.x - solution.x_free
        residual = problem.equality.d - problem.equality.C @ solution.x_free
        assert np.sqrt(step @ M @ step) <= bound * np.linalg.norm(residual) * (1 + 1e-9)
        assert solution.found and np.all(np.isfinite(solution.x))
    # Continuity: neighbouring samples (Δθ₂ = 1 mrad) give neighbouring solutions.
    damped_jump = np.max(np.linalg.norm(np.diff([s.x for _, s in damped], axis=0), axis=1))
    undamped_jump = np.max(np.linalg.norm(np.diff([s.x for _, s in undamped], axis=0), axis=1))
    assert damped_jump < 0.05 * damped_norms.max()
    # The undamped solve blows up at the singularity, the damped one does not.
    assert undamped_norms.max() > 100 * damped_norms.max()
    assert undamped_jump > 100 * damped_jump
    # Away from the singularity nothing is damped and the constraint holds exactly.
    far = np.abs(elbow_angles) > 0.15
    for (_, solution), is_far in zip(damped, far, strict=True):
        if is_far:
            assert solution.constraint_damping == 0.0
            assert solution.constraint_residual < 1e-9
    print(
        f"max ‖q̈‖ damped {damped_norms.max():.3g}, undamped {undamped_norms.max():.3g}; "
        f"max jump damped {damped_jump:.3g}, undamped {undamped_jump:.3g}"
    )
