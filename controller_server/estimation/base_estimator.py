"""Base pose and twist from an IMU and leg kinematics: a contact-aided invariant EKF.

Why this filter: the contact-aided right-invariant EKF (Hartley, Ghaffari, Eustice, Grizzle,
"Contact-aided invariant extended Kalman filtering for robot state estimation", IJRR 39(4),
2020; arXiv:1904.09251) puts orientation, velocity, position and stance-contact positions in
one matrix Lie group SE_{2+K}(3). Without biases its linearised error dynamics and
measurement Jacobian do not depend on the estimate, so a wrong initial yaw or position
does not corrupt the gains and the covariance keeps the true unobservable directions; a
quaternion EKF in the style of Bloesch et al. (RSS 2012) linearises about the estimate and
can become overconfident in yaw. IMU biases are appended outside the group as in the
paper's bias-augmented ("imperfect") InEKF, which gives up that independence only in the
bias columns. Section topics are cited, not numbers: the equations below were re-derived
and are checked by finite differences in the tests.

State (world frame W, IMU frame I; the filter runs at the IMU, where the propagation is
exact): ``X = (R, v, p, d_1 … d_K)`` with ``R = R_WI``, ``v``, ``p`` the IMU point's velocity
and position in W, ``d_k`` the stance contact points in W; biases ``b_g``, ``b_a`` in I.
Error ``η = X̂ X⁻¹ ≈ exp(ξ)`` (right-invariant), ``ζ = b̂ − b``; covariance order
``[ξ_R, ξ_v, ξ_p, ζ_g, ζ_a, ξ_d1 … ξ_dK]``.

* Propagation (paper: IMU propagation; mean integrated exactly for constant inputs):
  ``R⁺ = R Γ₀(ω dt)``, ``v⁺ = v + (R Γ₁(ω dt) a + g) dt``,
  ``p⁺ = p + v dt + (R Γ₂(ω dt) a + g/2) dt²`` with ``ω = ω̃ − b̂_g``, ``a = ã − b̂_a``;
  ``ξ̇ = A ξ + [Ad_X̂ w; w_b]``, ``A`` with ``∂ξ̇_v/∂ξ_R = [g]×``, ``∂ξ̇_p/∂ξ_v = I`` and the
  bias columns ``−Ad_X̂`` (rows ``−R``, ``−[v]× R``, ``−[p]× R``, ``−[d_k]× R`` for ``ζ_g``;
  ``−R`` in the ``ξ_v`` row for ``ζ_a``), evaluated at the mid-step state. ``A`` is
  nilpotent (``A⁴ = 0``), so ``Φ = I + A dt + (A dt)²/2 + (A dt)³/6`` is its exact
  exponential; ``Q_d = Φ G Q Gᵀ Φᵀ dt``.
* Leg kinematics (paper: forward-kinematic correction, right-invariant ``Y = X⁻¹ b``):
  ``y_k = R_WIᵀ (d_k − p)`` measured as ``R_BIᵀ (s_k(α) − r_BI)`` from the encoders;
  innovation ``z_k = R̂ y_k − (d̂_k − p̂)``, ``H_k = [0, 0, −I, 0, 0, …, I, …]``, noise
  ``R̂ R_BIᵀ (J Σ_α Jᵀ + σ_s² I) R_BI R̂ᵀ``; ``X̂⁺ = exp(δ_ξ) X̂``, ``b̂⁺ = b̂ + δ_ζ``,
  ``δ = K z``, covariance ``P − K H P``.
* Contacts (paper: adding and removing contacts): a contact entering stance is augmented with
  ``d̂_k = p̂ + R̂ y_k``, whose error ``ξ_dk = ξ_p + R̂ n`` copies the ``ξ_p`` rows of the
  covariance; one leaving stance is marginalised (its rows and columns dropped).

Observability (Hartley et al. 2018/2020; Bloesch et al. 2012): with a stance contact,
roll, pitch, velocity, the height above the stance feet and the gyro bias are observable,
and the accelerometer bias when the body rotates (a horizontal accelerometer bias is
otherwise indistinguishable from tilt: 0.1 m/s² is 0.6°). Yaw and horizontal position are
not: they drift as a random walk driven by the gyro noise, the not-yet-converged gyro bias
about the vertical and the foot-slip noise (a slipping foot pair can turn the base). Nothing
here bounds them without an external heading or position; the covariance (``BaseEstimate``,
``δθ_z`` and ``δp_xy``) grows to show it. In the synthetic 10 s test (BMI088 noise, 0.5 °/s
initial gyro bias) the yaw error stays within 0.7°. Heights are relative to the ground under
the stance feet at initialisation.

The base B carries the IMU at ``R_BI`` (IMU axes in B) and ``r_BI`` (IMU origin in B):
``R_WB = R_WI R_BIᵀ``, ``p_B = p_I − R_WB r_BI``, ``ω_B = R_BI ω_I``,
``v_B = v_I − R_WB (ω_B × r_BI)`` (the lever arm).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from controller_server.estimation.estimate import (
    STANDARD_GRAVITY,
    BaseEstimate,
    EstimatorInputError,
    EstimatorNoise,
    EstimatorPrior,
    ImuMount,
    checked_array,
    level_rotation,
)
from controller_server.estimation.inekf import (
    error_dynamics_matrix,
    error_transition_matrix,
    ground_innovation,
    kinematic_innovation,
    propagate_mean,
)
from controller_server.estimation.leg_kinematics import LegKinematics
from controller_server.estimation.lie import sek3_exp
from controller_server.math.spatial import cross, skew

__all__ = ["BaseEstimator"]


class BaseEstimator:
    """Contact-aided right-invariant EKF on SE_{2+K}(3) with IMU biases (see the module).

    Call :meth:`initialize` (or let the first :meth:`step` do it, the robot standing still),
    then :meth:`step` every IMU sample with the leg kinematics and contact flags of the same
    instant. Inputs are validated: anything not finite or misshapen raises
    :class:`EstimatorInputError` naming the field and leaves the filter as it was.
    """

    def __init__(
        self,
        contact_names: Sequence[str],
        *,
        imu_mount: ImuMount | None = None,
        noise: EstimatorNoise | None = None,
        prior: EstimatorPrior | None = None,
        gravity: float = STANDARD_GRAVITY,
        max_time_step_s: float = 0.05,
    ):
        """Set up an uninitialised filter.

        Args:
            contact_names: Contacts in the order of ``contact_flags`` and kinematics rows.
            imu_mount: IMU placement on the base (default: at the base origin, aligned).
            noise: Noise densities (default :class:`EstimatorNoise`).
            prior: Initial uncertainties (default :class:`EstimatorPrior`).
            gravity: Magnitude of gravity (m/s²).
            max_time_step_s: Longest ``dt`` accepted by :meth:`propagate`.

        Raises:
            EstimatorInputError: The mount's rotation is not a rotation matrix, or a bad
                ``max_time_step_s``.
        """
        self.contact_names = tuple(contact_names)
        mount = imu_mount or ImuMount()
        self._rotation_imu_to_base = checked_array(
            mount.rotation_imu_to_base, "imu_mount.rotation_imu_to_base", (3, 3)
        )
        self._position_imu_in_base = checked_array(
            mount.position_imu_in_base, "imu_mount.position_imu_in_base", (3,)
        )
        rotation = self._rotation_imu_to_base
        if not (
            np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-6) and np.linalg.det(rotation) > 0
        ):
            raise EstimatorInputError(
                "imu_mount.rotation_imu_to_base", f"not a rotation matrix: {rotation.tolist()}"
            )
        if not max_time_step_s > 0:
            raise EstimatorInputError("max_time_step_s", f"{max_time_step_s=} must be positive")
        self.noise = noise or EstimatorNoise()
        self.prior = prior or EstimatorPrior()
        self._gravity = np.array([0.0, 0.0, -gravity])
        self._max_time_step_s = max_time_step_s
        self.reset()

    def reset(self) -> None:
        """Forget the state: the next :meth:`step` initialises again."""
        self._rotation = np.eye(3)  # R_WI
        self._columns = np.zeros((2, 3))  # v_I, p_I, then one row per stance contact
        self._bias = np.zeros(6)  # [b_g, b_a] in I
        self._covariance = np.zeros((15, 15))
        self._stance: list[int] = []  # contact index of each contact column
        self._gyro_reading = np.zeros(3)  # last raw gyro, for ω_B with the current bias
        self.initialized = False

    # -- inputs --------------------------------------------------------------------------

    def _check_kinematics(
        self, kinematics: LegKinematics, contact_flags: Sequence[bool]
    ) -> tuple[np.ndarray, np.ndarray, list[bool]]:
        count = len(self.contact_names)
        positions = checked_array(
            kinematics.position_points_in_base, "kinematics.position_points_in_base", (count, 3)
        )
        jacobians = checked_array(kinematics.jacobians, "kinematics.jacobians", (count, 3, None))
        flags = [bool(flag) for flag in contact_flags]
        if len(flags) != count:
            raise EstimatorInputError("contact_flags", f"{len(flags)} flags for {count} contacts")
        return positions, jacobians, flags

    def _measurement_in_imu(self, position_in_base: np.ndarray, jacobian: np.ndarray):
        """``y = R_BIᵀ (s − r_BI)`` and its covariance in I (encoders + model error)."""
        rotation = self._rotation_imu_to_base
        covariance_in_base = self.noise.joint_position_noise**2 * (jacobian @ jacobian.T)
        covariance_in_base += self.noise.contact_position_noise**2 * np.eye(3)
        y = rotation.T @ (position_in_base - self._position_imu_in_base)
        return y, rotation.T @ covariance_in_base @ rotation

    # -- initialisation ------------------------------------------------------------------

    def initialize(
        self,
        kinematics: LegKinematics,
        contact_flags: Sequence[bool],
        *,
        specific_force_imu_in_imu: np.ndarray | None = None,
        orientation_base_in_world_xyzw: np.ndarray | None = None,
        position_base_in_world: np.ndarray | None = None,
        angular_velocity_imu_in_imu: np.ndarray | None = None,
    ) -> None:
        """Start from a standing pose.

        Orientation: given, else levelled on the accelerometer (yaw zero; valid when still).
        Position: given, else ``x = y = 0`` and the height that puts the lowest stance
        contact point on ``z = 0``. Velocity and biases start at zero; every stance contact
        is added to the state. ``angular_velocity_imu_in_imu`` (the gyro now) is the gyro
        bias when the prior says the robot stands still (:class:`EstimatorPrior`
        ``still_at_start``), else it gives the first estimate's angular velocity.

        Raises:
            EstimatorInputError: Bad input, or no orientation source or no stance contact to
                place the base on.
        """
        positions, _, flags = self._check_kinematics(kinematics, contact_flags)
        gyro = (
            np.zeros(3)
            if angular_velocity_imu_in_imu is None
            else checked_array(angular_velocity_imu_in_imu, "angular_velocity_imu_in_imu", (3,))
        )
        if orientation_base_in_world_xyzw is not None:
            quaternion = checked_array(
                orientation_base_in_world_xyzw, "orientation_base_in_world_xyzw", (4,)
            )
            norm = np.linalg.norm(quaternion)
            if not 0.5 < norm < 1.5:
                raise EstimatorInputError("orientation_base_in_world_xyzw", f"norm {norm:.3g}")
            rotation_base = pin.Quaternion(quaternion / norm).toRotationMatrix()
        elif specific_force_imu_in_imu is not None:
            force = checked_array(specific_force_imu_in_imu, "specific_force_imu_in_imu", (3,))
            if np.linalg.norm(force) < 0.5 * np.linalg.norm(self._gravity):
                raise EstimatorInputError(
                    "specific_force_imu_in_imu", f"{force.tolist()} is no gravity reading"
                )
            rotation_base = level_rotation(self._rotation_imu_to_base @ force)
        else:
            raise EstimatorInputError(
                "orientation_base_in_world_xyzw",
                "give an orientation or an accelerometer reading to initialise from",
            )
        if position_base_in_world is not None:
            position_base = checked_array(position_base_in_world, "position_base_in_world", (3,))
        elif any(flags):
            lowest = min((rotation_base @ positions[k])[2] for k in range(len(flags)) if flags[k])
            position_base = np.array([0.0, 0.0, -lowest])
        else:
            raise EstimatorInputError(
                "contact_flags", "no stance contact to place the base on; give a position"
            )
        self.reset()
        self._gyro_reading = gyro
        prior = self.prior
        gyro_bias_sigma = prior.gyro_bias
        if prior.still_at_start and angular_velocity_imu_in_imu is not None:
            self._bias[:3] = gyro  # still: the reading is the bias
            gyro_bias_sigma = prior.gyro_bias_at_rest
        self._rotation = rotation_base @ self._rotation_imu_to_base  # R_WI = R_WB R_BI
        position_imu = position_base + rotation_base @ self._position_imu_in_base
        self._columns = np.array([np.zeros(3), position_imu])
        sigma = np.concatenate(
            [
                [prior.roll_pitch_rad, prior.roll_pitch_rad, prior.yaw_rad],
                np.full(3, prior.velocity),
                np.full(3, prior.position),
                np.full(3, gyro_bias_sigma),
                np.full(3, prior.accel_bias),
            ]
        )
        # Conventional errors δv = ξ_v − [v]× ξ_R, δp = ξ_p − [p]× ξ_R (v = 0 here).
        to_invariant = np.eye(15)
        to_invariant[6:9, 0:3] = skew(position_imu)
        self._covariance = to_invariant @ np.diag(sigma**2) @ to_invariant.T
        self.initialized = True
        self.correct(kinematics, flags)

    # -- propagation ---------------------------------------------------------------------

    def propagate(
        self, angular_velocity_imu_in_imu: np.ndarray, specific_force_imu_in_imu: np.ndarray, dt
    ) -> None:
        """Integrate one IMU sample over ``dt`` s (Hartley et al. 2020, IMU propagation).

        Args:
            angular_velocity_imu_in_imu: Gyro reading (rad/s).
            specific_force_imu_in_imu: Accelerometer reading ``R_WIᵀ (a − g)`` (m/s²).
            dt: Time since the previous sample (s).

        Raises:
            EstimatorInputError: A non-finite reading, or ``dt`` not in ``(0, max]``.
        """
        gyro = checked_array(angular_velocity_imu_in_imu, "angular_velocity_imu_in_imu", (3,))
        accel = checked_array(specific_force_imu_in_imu, "specific_force_imu_in_imu", (3,))
        dt = float(checked_array(dt, "dt", ()))
        if not 0.0 < dt <= self._max_time_step_s:
            raise EstimatorInputError("dt", f"{dt=} s not in (0, {self._max_time_step_s}]")
        self._require_initialized()
        omega = gyro - self._bias[:3]
        accel = accel - self._bias[3:]
        self._gyro_reading = gyro
        # A and G at the mid-step state: the bias columns then match the exact transition
        # to O(dt³) (A itself changes with the state over the step).
        middle = propagate_mean(self._rotation, self._columns, omega, accel, self._gravity, dt / 2)
        a_matrix, g_matrix = error_dynamics_matrix(*middle, self._gravity)
        phi = error_transition_matrix(a_matrix, dt)
        noise = self.noise
        dim = len(self._covariance)
        q_diag = np.zeros(dim)
        q_diag[0:3] = noise.gyro_noise_density**2
        q_diag[3:6] = noise.accel_noise_density**2
        q_diag[9:12] = noise.gyro_bias_random_walk**2
        q_diag[12:15] = noise.accel_bias_random_walk**2
        q_diag[15:] = noise.contact_slip_random_walk**2
        phi_g = phi @ g_matrix
        self._covariance = phi @ self._covariance @ phi.T + (phi_g * q_diag) @ phi_g.T * dt
        self._rotation, self._columns = propagate_mean(
            self._rotation, self._columns, omega, accel, self._gravity, dt
        )

    # -- correction ----------------------------------------------------------------------

    def correct(self, kinematics: LegKinematics, contact_flags: Sequence[bool]) -> None:
        """Leg-kinematics correction, then contact bookkeeping (Hartley et al. 2020).

        Contacts that left stance are marginalised; those still in stance correct the
        state; those newly in stance are added at ``p̂ + R̂ y``.

        Raises:
            EstimatorInputError: Misshapen or non-finite kinematics or flags.
        """
        positions, jacobians, flags = self._check_kinematics(kinematics, contact_flags)
        self._require_initialized()
        kept = [i for i, k in enumerate(self._stance) if flags[k]]
        if len(kept) < len(self._stance):
            self._keep_contacts(kept)
        measured = [self._measurement_in_imu(positions[k], jacobians[k]) for k in range(len(flags))]
        if self._stance:
            self._update(measured)
        for k, in_stance in enumerate(flags):
            if in_stance and k not in self._stance:
                self._add_contact(k, *measured[k])

    def forget_contacts(self, contacts: Sequence[int]) -> None:
        """Marginalise these contacts (indices in ``contact_names``) if in stance.

        The next :meth:`correct` that flags them adds them afresh, at the point its
        kinematics then give: for a foot whose point on the ground changed (a foot that
        rolled onto an edge), the old point is no longer the one standing still.
        """
        kept = [i for i, k in enumerate(self._stance) if k not in set(contacts)]
        if len(kept) < len(self._stance):
            self._keep_contacts(kept)

    @property
    def rotation_base_in_world(self) -> np.ndarray:
        """``R_WB`` now (identity before :meth:`initialize`)."""
        return self._rotation @ self._rotation_imu_to_base.T

    def _keep_contacts(self, kept: list[int]) -> None:
        index = np.r_[0:15, [15 + 3 * i + j for i in kept for j in range(3)]].astype(int)
        self._covariance = self._covariance[np.ix_(index, index)]
        self._columns = np.vstack([self._columns[:2], self._columns[2:][kept]])
        self._stance = [self._stance[i] for i in kept]

    def _update(self, measured) -> None:
        dim = len(self._covariance)
        count = len(self._stance)
        ground = self.noise.flat_ground
        rows = 3 * count + (count if ground is not None else 0)
        h_matrix = np.zeros((rows, dim))
        innovation = np.zeros(rows)
        noise = np.zeros((rows, rows))
        for i, k in enumerate(self._stance):
            block = slice(3 * i, 3 * i + 3)
            y, covariance = measured[k]
            innovation[block], h_matrix[block] = kinematic_innovation(
                self._rotation, self._columns, i, y
            )
            noise[block, block] = self._rotation @ covariance @ self._rotation.T
            if ground is not None:
                row = 3 * count + i
                innovation[row], h_matrix[row] = ground_innovation(self._columns, i)
                noise[row, row] = ground**2
        p_ht = self._covariance @ h_matrix.T
        innovation_covariance = h_matrix @ p_ht + noise
        gain = np.linalg.solve(innovation_covariance, p_ht.T).T
        delta = gain @ innovation
        rotation_step, column_step = sek3_exp(np.r_[delta[0:9], delta[15:]])
        self._rotation = rotation_step @ self._rotation
        self._columns = self._columns @ rotation_step.T + column_step
        self._bias = self._bias + delta[9:15]
        # P − K S Kᵀ = P − K H P with the optimal gain; symmetrised against round-off.
        covariance = self._covariance - gain @ p_ht.T
        self._covariance = 0.5 * (covariance + covariance.T)

    def _add_contact(self, contact: int, y: np.ndarray, covariance: np.ndarray) -> None:
        dim = len(self._covariance)
        augment = np.zeros((dim + 3, dim))
        augment[:dim] = np.eye(dim)
        augment[dim:, 6:9] = np.eye(3)  # ξ_d = ξ_p + R̂ n
        expanded = augment @ self._covariance @ augment.T
        expanded[dim:, dim:] += self._rotation @ covariance @ self._rotation.T
        self._covariance = expanded
        self._columns = np.vstack([self._columns, self._columns[1] + self._rotation @ y])
        self._stance.append(contact)

    # -- one tick and outputs ------------------------------------------------------------

    def step(
        self,
        angular_velocity_imu_in_imu: np.ndarray,
        specific_force_imu_in_imu: np.ndarray,
        dt: float,
        kinematics: LegKinematics,
        contact_flags: Sequence[bool],
    ) -> BaseEstimate:
        """Propagate over ``dt`` and correct with the kinematics; initialise if needed.

        The first call (after construction or :meth:`reset`) levels the filter on the
        accelerometer reading and the stance feet (see :meth:`initialize`).
        """
        if not self.initialized:
            self.initialize(
                kinematics,
                contact_flags,
                specific_force_imu_in_imu=specific_force_imu_in_imu,
                angular_velocity_imu_in_imu=angular_velocity_imu_in_imu,
            )
        else:
            self._check_kinematics(kinematics, contact_flags)  # before changing anything
            self.propagate(angular_velocity_imu_in_imu, specific_force_imu_in_imu, dt)
            self.correct(kinematics, contact_flags)
        return self.estimate()

    def estimate(self) -> BaseEstimate:
        """The base state, its covariance and the stance contact points."""
        self._require_initialized()
        rotation_base = self._rotation @ self._rotation_imu_to_base.T
        offset = self._position_imu_in_base
        angular_velocity_base = self._rotation_imu_to_base @ (self._gyro_reading - self._bias[:3])
        velocity_base = self._columns[0] - rotation_base @ cross(angular_velocity_base, offset)
        position_base = self._columns[1] - rotation_base @ offset
        # Invariant errors to conventional base errors (see BaseEstimate.covariance).
        to_base = np.zeros((15, len(self._covariance)))
        to_base[:, :15] = np.eye(15)
        to_base[3:6, 0:3] = -skew(velocity_base)
        to_base[3:6, 9:12] = -rotation_base @ skew(offset) @ self._rotation_imu_to_base
        to_base[6:9, 0:3] = -skew(position_base)
        quaternion = pin.Quaternion(rotation_base)
        quaternion.normalize()
        return BaseEstimate(
            position_base_in_world=position_base,
            orientation_base_in_world_xyzw=np.array(quaternion.coeffs()),
            linear_velocity_base_in_world=velocity_base,
            angular_velocity_base_in_base=angular_velocity_base,
            gyro_bias_in_imu=self._bias[:3].copy(),
            accel_bias_in_imu=self._bias[3:].copy(),
            position_contacts_in_world={
                self.contact_names[k]: self._columns[2 + i].copy()
                for i, k in enumerate(self._stance)
            },
            covariance=to_base @ self._covariance @ to_base.T,
        )

    def _require_initialized(self) -> None:
        if not self.initialized:
            raise EstimatorInputError("state", "the estimator is not initialised: call initialize")
