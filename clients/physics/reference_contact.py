"""The reference simulator's ground contact: penalty forces at the robot's contact points.

:class:`PenaltyContact` holds the contact points of
:class:`~clients.physics.reference.ReferenceBackend`, where they are, which touch the
ground and where their friction springs are anchored, and solves the forces that act
during a step and the wrench of each contact.

Ground contact (thesis ch. 4.2: penalty forces) acts at the contact points
of the robot's reading shared with the server
(:mod:`controller_server.models.description`): the corners of each
``*_sole`` box site, or of the soles found from the feet's collision
geometry, or the contacts a scenario names. Per point below the ground,
with depth ``d``:

* normal: ``f_n = max(0, k d − c ż)`` (pushes, never pulls);
* tangential: a spring–damper anchored where the point touched down,
  ``f_t = −k_t (p − a) − c_t ṗ`` in the ground plane, capped at ``μ f_n``.
  When the cap binds the point slides and its anchor is dragged along so
  the spring holds exactly ``μ f_n`` (Coulomb sliding); below the cap it
  sticks, with no creep. A regularized Coulomb law
  (``−μ f_n v / max(|v|, v_slip)``) was rejected: it creeps at
  ``v_slip · f_t / (μ f_n)`` under any sideways load, and a small
  ``v_slip`` is a stiff damper.

The springs are explicit; the dampers are taken at the end-of-step
velocity (linearly implicit, see :meth:`PenaltyContact._solve_contact`),
which is stable for any ``c``. Explicit dampers would be capped by the
lightest link: the thesis foot's roll inertia about the ankle is
8·10⁻⁴ kg·m², which bounds ``c`` to about 140 N·s/m per point at 1 ms.

Defaults, per contact point (four per foot): ``k = k_t = 2·10⁵ N/m`` sinks
the 65 kg thesis humanoid 0.4 mm on average; ``c = c_t = 10⁴ N·s/m`` makes
the ground a firm, well damped floor (a rubber sole on concrete): settling
time ``c/k`` = 50 ms, and a foot resists rocking with about
800 N·m·s/rad. The damping is what a 1 kHz whole-body controller needs.
Its ankle torques assume a rigid ground; any mismatch rocks the light foot
at ``Δτ / (c Σ r²)`` rad/s within a step, the tracking damping answers that
ankle velocity with whole-body torques (``k_d · I_body``), and the loop
gain is about ``k_d I_body / (c Σ r²)``. At the earlier ``c = 1500 N·s/m``
that gain was about 5 and quiet standing diverged in a period-2 oscillation
within 30 ms; at ``10⁴`` it is below 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from clients.physics.backend import ContactPoint
from clients.physics.errors import UnsupportedModel
from clients.physics.spatial import skew

__all__ = [
    "DEFAULT_CONTACT_DAMPING_NS_PER_M",
    "DEFAULT_CONTACT_STIFFNESS_N_PER_M",
    "PenaltyContact",
]

DEFAULT_CONTACT_STIFFNESS_N_PER_M = 2.0e5
"""Normal (and tangential) penalty stiffness per contact point."""
DEFAULT_CONTACT_DAMPING_NS_PER_M = 1.0e4
"""Normal (and tangential) penalty damping per contact point (implicit: stable for any value)."""


@dataclass(frozen=True)
class _ContactBlock:
    """The points of one contact: all fixed to one joint, reported about one site frame.

    Attributes:
        joint: Pinocchio joint the points are fixed to.
        points: Their rows in the per-point arrays.
        points_in_joint: ``(k, 3)`` point positions in the joint frame.
        skew_stack: ``(3k, 3)`` stacked ``[p_i]×``, so that the point
            velocities in the joint frame are ``v − skew_stack ω``.
        site_position_in_joint: Origin of the contact's site frame.
        homogeneous_points: ``(k + 1, 4)`` the points, then the site origin,
            in homogeneous coordinates.
        velocity_map: ``(3k, 6)`` ``[I; …; I | −skew_stack]``: point
            velocities in the joint frame from the joint's spatial velocity.
    """

    joint: int
    points: slice
    points_in_joint: np.ndarray
    skew_stack: np.ndarray
    site_position_in_joint: np.ndarray
    homogeneous_points: np.ndarray
    velocity_map: np.ndarray

    @classmethod
    def build(
        cls, joint: int, points: slice, points_in_joint: np.ndarray, site: np.ndarray
    ) -> _ContactBlock:
        """A block with its skew matrices precomputed."""
        skew_stack = np.vstack([skew(p) for p in points_in_joint]).reshape(-1, 3)
        homogeneous = np.hstack(
            [np.vstack([points_in_joint, site]), np.ones((len(points_in_joint) + 1, 1))]
        )
        velocity_map = np.hstack([np.tile(np.eye(3), (len(points_in_joint), 1)), -skew_stack])
        return cls(joint, points, points_in_joint, skew_stack, site, homogeneous, velocity_map)


def _solve_sliding(
    system: np.ndarray,
    rhs: np.ndarray,
    keep: np.ndarray,
    sliding: np.ndarray,
    friction: np.ndarray,
) -> np.ndarray:
    """``(count, 3)`` forces solving the kept points' rows of ``system f = rhs``, 0 elsewhere.

    A sliding point's tangential force is ``friction[point] · f_n`` (``friction`` is
    ``μ d``, ``(count, 2)``): its tangential unknowns become its normal's, its tangential
    equations are dropped (``f = P u``, solve ``(system P)_rows u = rhs_rows``).
    """
    count = keep.size
    rows = np.flatnonzero(np.repeat(keep, 3) & ~(np.repeat(sliding, 3) & _TANGENTIAL[count]))
    forces = np.zeros(3 * count)
    if not sliding.any():
        forces[rows] = np.linalg.solve(system[np.ix_(rows, rows)], rhs[rows])
        return forces.reshape(count, 3)
    mapping = np.zeros((3 * count, rows.size))
    mapping[rows, np.arange(rows.size)] = 1.0
    for point in np.flatnonzero(sliding):
        normal = int(np.searchsorted(rows, 3 * point + 2))
        mapping[3 * point : 3 * point + 2, normal] = friction[point]
    return (mapping @ np.linalg.solve(system[rows] @ mapping, rhs[rows])).reshape(count, 3)


class _TangentialRows(dict):
    """``count`` → ``(3 · count,)`` mask of the x and y rows of ``count`` points."""

    def __missing__(self, count: int) -> np.ndarray:
        mask = np.tile([True, True, False], count)
        self[count] = mask
        return mask


_TANGENTIAL = _TangentialRows()


class PenaltyContact:
    """Penalty ground contact of one robot's contact points (see the module docstring).

    The backend updates the kinematics and integrates. After each kinematics update it
    places the points (:meth:`place_points`); in a step it asks for the contact forces,
    which are added to the free acceleration (:meth:`step_forces`). The model and data
    are the backend's.

    Args:
        model: The Pinocchio model being integrated.
        data: Its data, whose kinematics the backend updates.
        points: The contact points, contacts in order.
        friction_coefficient: Coulomb μ between soles and ground.
        timestep_s: Integration step (s).
        ground_height_m: Height of the flat ground (m).
        contact_stiffness_N_per_m: Normal penalty stiffness ``k`` per point.
        contact_damping_Ns_per_m: Normal penalty damping ``c`` per point.
        tangential_stiffness_N_per_m: Stick spring ``k_t`` per point.
        tangential_damping_Ns_per_m: Stick damper ``c_t`` per point.

    Attributes:
        contact_points: The points, contacts in order.
        contact_names: The contacts, in order.
        foot_frames: The contacts' body frames and their parents (the feet).

    Raises:
        UnsupportedModel: The points of one contact are fixed to several frames.
    """

    def __init__(
        self,
        model: pin.Model,
        data: pin.Data,
        points: list[ContactPoint],
        *,
        friction_coefficient: float,
        timestep_s: float,
        ground_height_m: float,
        contact_stiffness_N_per_m: float,
        contact_damping_Ns_per_m: float,
        tangential_stiffness_N_per_m: float,
        tangential_damping_Ns_per_m: float,
    ):
        self._model = model
        self._data = data
        self.friction_coefficient = friction_coefficient
        self.timestep_s = timestep_s
        self.ground_height_m = ground_height_m
        self.contact_stiffness_N_per_m = contact_stiffness_N_per_m
        self.contact_damping_Ns_per_m = contact_damping_Ns_per_m
        self.tangential_stiffness_N_per_m = tangential_stiffness_N_per_m
        self.tangential_damping_Ns_per_m = tangential_damping_Ns_per_m
        self._setup_contacts(points)

    def _setup_contacts(self, points: list[ContactPoint]) -> None:
        """The contacts' blocks of points and the per-point arrays."""
        self.contact_points = points
        self.contact_names: list[str] = list(dict.fromkeys(p.contact for p in points))
        self.foot_frames: set[str] = set()
        self._blocks: list[_ContactBlock] = []
        start = 0
        for contact in self.contact_names:
            members = [p for p in points if p.contact == contact]
            frames = {p.frame for p in members}
            if len(frames) != 1:
                raise UnsupportedModel(f"contact {contact!r} spans frames {sorted(frames)}")
            site = members[0].frame
            frame = self._model.frames[self._model.getFrameId(site)]
            self.foot_frames.add(site if frame.type == pin.FrameType.BODY else "")
            self.foot_frames.add(self._model.frames[frame.parentFrame].name)
            points_in_joint = np.array(
                [frame.placement.act(np.array(p.point_in_frame, float)) for p in members]
            )
            self._blocks.append(
                _ContactBlock.build(
                    frame.parentJoint,
                    slice(start, start + len(members)),
                    points_in_joint,
                    frame.placement.translation.copy(),
                )
            )
            start += len(members)
        self._point_position = np.zeros((start, 3))
        self._point_velocity = np.zeros((start, 3))
        self._point_force = np.zeros((start, 3))
        self._touching = np.zeros(start, dtype=bool)
        self._anchor = np.zeros((start, 2))
        self._anchored = np.zeros(start, dtype=bool)
        self._damping_per_row = np.tile(
            [
                self.tangential_damping_Ns_per_m,
                self.tangential_damping_Ns_per_m,
                self.contact_damping_Ns_per_m,
            ],
            start,
        )
        self._all_rows = np.arange(3 * start)
        self._point_contact = np.zeros(start, dtype=int)
        self._contact_sum = np.zeros((len(self._blocks), start))
        for index, block in enumerate(self._blocks):
            self._point_contact[block.points] = index
            self._contact_sum[index, block.points] = 1.0
        self._point_wrench = np.zeros((start, 6))
        self._site_origin = np.zeros((len(self._blocks), 3))
        self._contact_wrench = np.zeros((len(self._blocks), 6))

    # ------------------------------------------------------------- the backend's

    def place_points(self) -> None:
        """Contact points, touching set and anchors at the kinematics in ``data``.

        The backend runs ``pinocchio.forwardKinematics`` (positions and velocities) first.
        """
        data = self._data
        position, velocity = self._point_position, self._point_velocity
        for index, block in enumerate(self._blocks):
            transform = data.oMi[block.joint].homogeneous
            rotation = transform[:3, :3]
            placed = block.homogeneous_points @ transform[:3].T
            position[block.points] = placed[:-1]
            self._site_origin[index] = placed[-1]
            velocity_in_joint = block.velocity_map @ data.v[block.joint].vector
            velocity[block.points] = velocity_in_joint.reshape(-1, 3) @ rotation.T
        touching = position[:, 2] < self.ground_height_m
        # A spring anchor is set where a point touches down and forgotten at lift-off.
        landing = touching & ~self._anchored
        if landing.any():
            self._anchor[landing] = position[landing, :2]
        self._anchored = touching
        self._touching = touching

    def flags(self) -> list[bool]:
        """Per contact: is any of its points below the ground (as last placed)."""
        return (self._contact_sum @ self._touching > 0.0).tolist()

    def clear_anchors(self) -> None:
        """Forget every spring anchor (a reset): each point anchors where it next touches."""
        self._anchored[:] = False

    def step_forces(self, q: np.ndarray, v: np.ndarray, acceleration: np.ndarray) -> None:
        """The forces acting during the step from ``(q, v)``, and the contacts' wrenches.

        The points are placed at ``(q, v)``. ``acceleration`` (``a_free`` on entry)
        gets ``M⁻¹ Jᵀ f`` added in place (:meth:`_solve_contact`).
        """
        self._point_force[:] = 0.0
        if self._touching.any():
            self._solve_contact(q, v, acceleration)
        self._update_wrenches()

    def report_explicit_forces(self) -> None:
        """Forces with explicit dampers at the current state (what is reported after reset)."""
        self._point_force[:] = 0.0
        points = np.flatnonzero(self._touching)
        if points.size:
            forces = (
                self._spring_forces(points)
                - self._damping_per_row[: 3 * points.size].reshape(-1, 3)
                * self._point_velocity[points]
            )
            forces[:, 2] = np.maximum(forces[:, 2], 0.0)
            self._limit_friction(points, forces, drag_anchors=False)
            self._point_force[points] = forces
        self._update_wrenches()

    def _update_wrenches(self) -> None:
        """Per contact: summed point forces and their moment about the site origin."""
        arms = self._point_position - self._site_origin[self._point_contact]
        self._point_wrench[:, :3] = self._point_force
        force = self._point_force
        torque = self._point_wrench[:, 3:]
        torque[:, 0] = arms[:, 1] * force[:, 2] - arms[:, 2] * force[:, 1]
        torque[:, 1] = arms[:, 2] * force[:, 0] - arms[:, 0] * force[:, 2]
        torque[:, 2] = arms[:, 0] * force[:, 1] - arms[:, 1] * force[:, 0]
        np.matmul(self._contact_sum, self._point_wrench, out=self._contact_wrench)

    def wrenches(self) -> np.ndarray:
        """``(contacts, 6)`` summed point forces and their moment about each site origin (copy)."""
        return self._contact_wrench.copy()

    def point_forces(self) -> np.ndarray:
        """``(points, 3)`` force at each point (copy)."""
        return self._point_force.copy()

    def point_positions(self) -> np.ndarray:
        """``(points, 3)`` position of each point as last placed (copy)."""
        return self._point_position.copy()

    # ------------------------------------------------------------------ the solve

    def _spring_forces(self, points: np.ndarray) -> np.ndarray:
        """``(len(points), 3)`` spring part of the penalty force at these points."""
        spring = np.empty((points.size, 3))
        spring[:, :2] = -self.tangential_stiffness_N_per_m * (
            self._point_position[points, :2] - self._anchor[points]
        )
        spring[:, 2] = self.contact_stiffness_N_per_m * (
            self.ground_height_m - self._point_position[points, 2]
        )
        return spring

    def _limit_friction(
        self, points: np.ndarray, forces: np.ndarray, drag_anchors: bool = True
    ) -> None:
        """Clamp ``forces`` (in place) to the Coulomb cone; sliding points drag their anchors."""
        tangential = forces[:, :2]
        norm = np.hypot(tangential[:, 0], tangential[:, 1])
        limit = self.friction_coefficient * forces[:, 2]
        sliding = norm > limit
        if sliding.any():
            tangential[sliding] *= (limit[sliding] / norm[sliding])[:, None]
            if not drag_anchors:
                return
            self._anchor[points[sliding]] = (
                self._point_position[points[sliding], :2]
                + tangential[sliding] / self.tangential_stiffness_N_per_m
            )

    def _contact_jacobian(self, q: np.ndarray) -> np.ndarray:
        """``(3 · points, nv)`` world-axes velocity Jacobian of every contact point at ``q``."""
        model, data = self._model, self._data
        nv = model.nv
        pin.computeJointJacobians(model, data, q)
        rows = []
        for block in self._blocks:
            jacobian = pin.getJointJacobian(model, data, block.joint, pin.ReferenceFrame.LOCAL)
            count = block.points_in_joint.shape[0]
            in_joint = jacobian[None, :3] - (block.skew_stack @ jacobian[3:]).reshape(count, 3, nv)
            rows.append((data.oMi[block.joint].rotation @ in_joint).reshape(3 * count, nv))
        return np.vstack(rows)

    def _solve_contact(self, q: np.ndarray, v: np.ndarray, acceleration: np.ndarray) -> None:
        """Penalty forces with the dampers taken at the end-of-step velocity.

        With ``J`` the contact Jacobian, ``G = J M⁻¹ Jᵀ``, ``C`` the dampers and
        ``f_s`` the springs, the force that acts during the step solves
        ``f = f_s − C (J (v + Δt a_free) + Δt G f)``, i.e.
        ``(I + Δt C G) f = f_s − C J (v + Δt a_free)``. Points that would
        pull are released and points whose force leaves the friction cone
        slide, each time solving again (:meth:`_coulomb_solve`).
        ``acceleration`` (``a_free`` on entry) gets ``M⁻¹ Jᵀ f`` added in
        place.

        If every point would pull, the coupling is to blame: the stick dampers
        ask a sliding foot for more tangential force than friction allows,
        and through ``G`` that pulls the normals below zero (seen on a toe
        edge sliding back at 0.3 m/s: the foot then sank with no force at
        all). The normals are then solved alone, ``(I + Δt C_n G_nn) f_n =
        f_s,n − C_n J_n (v + Δt a_free)``, and the tangential forces taken
        explicitly, clamped to the cone.
        """
        model, data, step_s = self._model, self._data, self.timestep_s
        points = np.flatnonzero(self._touching)
        jacobian = self._contact_jacobian(q)
        if points.size == self._touching.size:
            rows = self._all_rows
        else:
            rows = (3 * points[:, None] + np.arange(3)).reshape(-1)
            jacobian = jacobian[rows]
        # Pinocchio ≥ 4 fills the whole (symmetric) M⁻¹.
        inverse_mass = pin.computeMinverse(model, data, q)
        response = inverse_mass @ jacobian.T
        damping = self._damping_per_row[rows]
        system = (step_s * damping)[:, None] * (jacobian @ response)
        system.flat[:: rows.size + 1] += 1.0
        rhs = self._spring_forces(points).reshape(-1) - damping * (
            jacobian @ (v + step_s * acceleration)
        )
        forces, keep = self._coulomb_solve(system, rhs)
        if not keep.any():
            self._solve_normals_alone(points, jacobian, response, rhs, acceleration)
            return
        active = points[keep]
        self._limit_friction(active, forces)
        self._point_force[active] = forces
        if not keep.all():
            response = response[:, np.repeat(keep, 3)]
        acceleration += response @ forces.reshape(-1)

    def _coulomb_solve(self, system: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Solve ``system f = rhs``, no point pulling and none outside its friction cone.

        A point that would pull is released (its rows dropped). A point whose tangential
        force leaves the friction cone slides: its tangential force is ``μ f_n d``, a
        column of the system in its normal force (its tangential equations dropped), so
        that the other points' forces, normals included, are solved with the sliding
        friction the step really has. ``d`` is the direction the stick solution pushed
        it (the force that would stop it within the step). Iterating ``d`` toward the
        point's end-of-step slip instead circled without settling on slow points.

        Clamping after a stick solve instead kept the normals that the (impossible) stick
        forces implied: a foot twisting on its edge was asked thousands of newtons
        sideways, and through ``G`` its normals came out pulling; the weight carried swung
        between 0.25 and 2.4 m g, and in a twisting jump the soles sank 2.5 cm with no
        force at all. Each pass releases a point or lets one slide, so there are at most
        ``2 · count + 1``.

        Returns:
            ``(kept points, 3)`` forces and the ``(count,)`` mask of the points kept.
        """
        mu = self.friction_coefficient
        count = rhs.size // 3
        keep = np.ones(count, dtype=bool)
        direction = np.full((count, 2), np.nan)  # slip direction of the sliding points
        for _ in range(2 * count + 1):
            sliding = np.isfinite(direction[:, 0]) & keep
            forces = _solve_sliding(system, rhs, keep, sliding, mu * direction)
            pulling = keep & ~(forces[:, 2] >= 0.0)  # NaN (a diverged state) releases too
            if pulling.any():
                keep &= ~pulling
                if not keep.any():
                    break
                continue
            tangential = np.hypot(forces[:, 0], forces[:, 1])
            leaving = keep & ~sliding & (tangential > mu * forces[:, 2] * (1.0 + 1e-9))
            if not leaving.any():
                break
            direction[leaving] = forces[leaving, :2] / tangential[leaving, None]
        return forces[keep], keep

    def _solve_normals_alone(
        self,
        points: np.ndarray,
        jacobian: np.ndarray,
        response: np.ndarray,
        rhs: np.ndarray,
        acceleration: np.ndarray,
    ) -> None:
        """The normal forces of ``points`` without the tangential coupling (see ``_solve_contact``).

        ``jacobian``, ``response`` and ``rhs`` hold the rows of ``points`` (x, y, z each);
        ``rhs`` is the coupled right-hand side, whose tangential rows are the explicit
        tangential forces.
        """
        normal = np.arange(2, 3 * points.size, 3)
        damping = self._damping_per_row[normal]
        system = (self.timestep_s * damping)[:, None] * (jacobian[normal] @ response[:, normal])
        system.flat[:: normal.size + 1] += 1.0
        keep = np.ones(points.size, dtype=bool)
        while keep.any():
            forces_normal = np.linalg.solve(system[np.ix_(keep, keep)], rhs[normal][keep])
            pulling = ~(forces_normal >= 0.0)  # NaN (a diverged state) releases too
            if not pulling.any():
                break
            keep[np.flatnonzero(keep)[pulling]] = False
        if not keep.any():
            return
        forces = rhs.reshape(-1, 3)[keep].copy()
        forces[:, 2] = forces_normal
        active = points[keep]
        self._limit_friction(active, forces)
        self._point_force[active] = forces
        acceleration += response[:, np.repeat(keep, 3)] @ forces.reshape(-1)
