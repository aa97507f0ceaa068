"""``ankle`` and ``swing``: feet in flight, placed by a behaviour (de Lasa et al. 2010, §5–6).

Both follow references a hosted behaviour gives for the tick
(:class:`~controller_server.behaviors.Targets`): ``ankle`` the feet's offsets from the CM
in a jump's flight (E_ankle, §5), ``swing`` the swing foot toward its foothold (E_swing,
§6.1). Without those targets, or at weight 0, they have no rows.
"""

from __future__ import annotations

from controller_server.features import Objective
from controller_server.features.point_from_com import compute_point_from_com_objective
from controller_server.features.setpoint import critical_damping
from controller_server.features.swing_foot import compute_swing_objective
from controller_server.tasks.task import Task, Tick

__all__ = ["AnkleTask", "SwingTask"]


class AnkleTask(Task):
    """Each foot at its offset from the CM, turned as the behaviour asks (``ankle_stiffness``)."""

    def __init__(self, name: str = "ankle"):
        super().__init__(name)

    def rows(self, tick: Tick, weight: float) -> Objective | None:
        """Rows of the feet relative to the CM; none without a behaviour's feet or at weight 0."""
        feet = None if tick.targets is None else tick.targets.feet_from_com
        if weight <= 0 or feet is None:
            return None
        p, terms = tick.params, tick.terms
        stiffness = p["ankle_stiffness"]
        return compute_point_from_com_objective(
            [jacobian[:3] for jacobian in terms.support_jacobians],
            [drift[:3] for drift in terms.support_drifts],
            terms.position_contact_frames_in_world,
            tick.v,
            terms.momentum,
            terms.total_mass,
            terms.position_com_in_world,
            feet.offsets_in_world,
            stiffness,
            critical_damping(stiffness, p["damping_ratio"]),
            weight,
            rotations=[tick.data.oMf[c.frame_id].rotation for c in tick.robot.contacts],
            reference_rotations=feet.rotations_in_world,
            angular_jacobians=[jacobian[3:] for jacobian in terms.support_jacobians],
            angular_drifts=[drift[3:] for drift in terms.support_drifts],
        )


class SwingTask(Task):
    """The swing foot along the behaviour's step toward its foothold, lifted by the step height."""

    def __init__(self, name: str = "swing"):
        super().__init__(name)

    def rows(self, tick: Tick, weight: float) -> Objective | None:
        """Rows of the swing foot; none without a behaviour's swing or at weight 0."""
        swing = None if tick.targets is None else tick.targets.swing
        if weight <= 0 or swing is None:
            return None
        terms, foot = tick.terms, swing.contact
        return compute_swing_objective(
            swing,
            tick.time_s,
            terms.support_jacobians[foot],
            terms.support_drifts[foot],
            terms.position_contact_frames_in_world[foot],
            tick.data.oMf[tick.robot.contacts[foot].frame_id].rotation,
            tick.v,
            swing.stiffness,
            critical_damping(swing.stiffness, tick.params["damping_ratio"]),
            weight,
        )
