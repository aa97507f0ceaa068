"""Metrics of a simulated run: did it stay up, and how well did it track and balance."""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from clients.layout import joint_slices
from clients.physics.model_file import describe_model
from clients.sim.runner import RunRecord
from clients.sim.scenario import Scenario, scenario_warnings

__all__ = [
    "JOINT_GROUPS",
    "START_OFFSET_NOTE_M",
    "asks_behavior",
    "base_estimate_error_series",
    "base_estimate_errors",
    "compute_metrics",
    "jump_metrics",
    "scenario_kind",
    "sole_and_com_series",
    "start_pose_note",
    "strictly_inside",
    "touchdowns",
    "walking_metrics",
]

AIRBORNE_M = 0.005
"""The soles count as off the ground when the lowest sole point is this high (m)."""

JOINT_GROUPS = {
    "legs": ("hip", "knee", "ankle"),
    "arms": ("shoulder", "elbow", "wrist"),
}
"""Joint groups by name fragment; the rest is ``torso`` (back, neck, tail, …)."""


def strictly_inside(point_xy: np.ndarray, polygon_xy: np.ndarray, margin_m: float = 1e-3) -> bool:
    """Whether a point is inside a counter-clockwise convex polygon, ``margin_m`` from its edges."""
    if len(polygon_xy) < 3 or not np.all(np.isfinite(point_xy)):
        return False
    edges = np.roll(polygon_xy, -1, axis=0) - polygon_xy
    to_point = point_xy - polygon_xy
    lengths = np.linalg.norm(edges, axis=1)
    signed_distance = (edges[:, 0] * to_point[:, 1] - edges[:, 1] * to_point[:, 0]) / lengths
    return bool(np.all(signed_distance > margin_m))


def _group(name: str) -> str:
    return next((g for g, words in JOINT_GROUPS.items() if any(w in name for w in words)), "torso")


def _joint_errors_rad(record: RunRecord) -> dict[str, np.ndarray]:
    """Per joint group, the deviation of every joint from its initial position over time."""
    joints = list(record.welcome.joints)
    slices = joint_slices(joints)
    initial = record.states[0].joint_position
    errors: dict[str, list[np.ndarray]] = {}
    positions = np.array([s.joint_position for s in record.states])
    for joint in joints:
        q_slice = slices[joint.name][0]
        if joint.kind == "ball":
            relative = Rotation.from_quat(initial[q_slice]).inv() * Rotation.from_quat(
                positions[:, q_slice]
            )
            error = relative.magnitude()
        else:
            error = np.abs(positions[:, q_slice][:, 0] - initial[q_slice][0])
        errors.setdefault(_group(joint.name), []).append(error)
    return {group: np.array(values) for group, values in errors.items()}


def _foot_slip_and_rotation(record: RunRecord) -> tuple[float, float]:
    """Largest slide (m) and turn (rad) of a sole frame while the controller supports on it.

    Supports are the controller's (``diagnostics.supports``: contact flags and
    ``support_mask``), so a swinging foot that brushes the ground is not
    counted. Each stance is measured from the sole frame's pose at the tick
    the foot became a support, from the simulated states (Pinocchio forward kinematics
    of the scenario's MJCF): a planted foot neither slides nor rocks.
    """
    model = describe_model(record.scenario.model).model
    data = model.createData()
    frames = [model.getFrameId(contact.frame) for contact in record.welcome.contacts]
    anchors: list[pin.SE3 | None] = [None] * len(frames)
    slip_m = rotation_rad = 0.0
    for state, flags in zip(record.states, _controller_supports(record), strict=True):
        base = [state.position_base_in_world, state.orientation_base_in_world_xyzw]
        q = np.concatenate([*base, state.joint_position])
        pin.framesForwardKinematics(model, data, q)
        for index, (frame, on) in enumerate(zip(frames, flags, strict=True)):
            if not on:
                anchors[index] = None
                continue
            pose = data.oMf[frame]
            anchor = anchors[index]
            if anchor is None:
                anchors[index] = pose.copy()
                continue
            slip_m = max(slip_m, float(np.linalg.norm((pose.translation - anchor.translation)[:2])))
            turn = pin.log3(anchor.rotation.T @ pose.rotation)
            rotation_rad = max(rotation_rad, float(np.linalg.norm(turn)))
    return slip_m, rotation_rad


def sole_and_com_series(record: RunRecord) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per state: the lowest sole point's height, the CM height (m) and the feet's heading (rad).

    Pinocchio forward kinematics of the scenario's model at the simulated states. The
    heading is that of the mean x axis of the sole frames (the pelvis may yaw on the
    hips), unwrapped, so a turn past ±180° keeps counting.
    """
    model = describe_model(record.scenario.model).model
    data = model.createData()
    frames = [model.getFrameId(contact.frame) for contact in record.welcome.contacts]
    points = [np.array(contact.points_in_frame) for contact in record.welcome.contacts]
    soles, coms, headings = [], [], []
    for state in record.states:
        q = np.concatenate(
            [
                state.position_base_in_world,
                state.orientation_base_in_world_xyzw,
                state.joint_position,
            ]
        )
        pin.framesForwardKinematics(model, data, q)
        soles.append(
            min(
                float(_points_in_world(data.oMf[frame], sole)[:, 2].min())
                for frame, sole in zip(frames, points, strict=True)
            )
        )
        coms.append(float(pin.centerOfMass(model, data, q)[2]))
        x_axes = sum(data.oMf[frame].rotation[:2, 0] for frame in frames)
        headings.append(float(np.arctan2(x_axes[1], x_axes[0])))
    return np.array(soles), np.array(coms), np.unwrap(np.array(headings))


def _points_in_world(placement: pin.SE3, points_in_frame: np.ndarray) -> np.ndarray:
    return points_in_frame @ placement.rotation.T + placement.translation


def jump_metrics(record: RunRecord) -> dict[str, float | bool]:
    """A jump's height, flight, landing and turn, from the simulated states.

    ``clearance_m``: highest the lowest sole point rose above where it started;
    ``com_rise_m``: highest CM above its height at the start; ``flight_s``:
    longest stretch with every sole above :data:`AIRBORNE_M`; ``landed``: did not
    fall and every sole is down over the run's last 0.3 s; ``turn_deg``: change of the
    feet's heading from the first state to the last.
    """
    soles, coms, headings = sole_and_com_series(record)
    period_s = 1.0 / record.scenario.control_rate_hz
    airborne = soles - soles[0] > AIRBORNE_M
    longest = current = 0
    for up in airborne:
        current = current + 1 if up else 0
        longest = max(longest, current)
    last = max(1, round(0.3 / period_s))
    return {
        "clearance_m": float(soles.max() - soles[0]),
        "com_rise_m": float(coms.max() - coms[0]),
        "flight_s": longest * period_s,
        "landed": bool(not record.fell and not airborne[-last:].any()),
        "turn_deg": float(np.degrees(headings[-1] - headings[0])),
    }


def base_estimate_error_series(record: RunRecord) -> dict[str, np.ndarray]:
    """Per tick with a ``base_estimate`` (``base_state = "imu"``), its error against the truth.

    Against the true state sent at that tick: ``tilt_deg``, the angle between the true and
    estimated up axes in the base frame (roll and pitch, not yaw); ``velocity_m_per_s``, the
    norm of the base velocity error (world); ``height_m``, estimated minus true base height;
    ``yaw_deg``, the heading error (unobservable: it drifts); and ``time_s``. Empty arrays
    when no tick has an estimate.
    """
    rows = []
    for time_s, state, command in zip(record.time_s, record.states, record.commands, strict=True):
        estimate = None if command.diagnostics is None else command.diagnostics.base_estimate
        if estimate is None:
            continue
        rotation_true = Rotation.from_quat(state.orientation_base_in_world_xyzw)
        rotation_estimated = Rotation.from_quat(estimate.orientation_base_in_world_xyzw)
        up_true = rotation_true.inv().apply([0.0, 0.0, 1.0])
        up_estimated = rotation_estimated.inv().apply([0.0, 0.0, 1.0])
        cosine = np.clip(float(up_true @ up_estimated), -1.0, 1.0)
        velocity_error = (
            estimate.linear_velocity_base_in_world - state.linear_velocity_base_in_world
        )
        rows.append(
            (
                time_s,
                np.degrees(np.arccos(cosine)),
                float(np.linalg.norm(velocity_error)),
                estimate.position_base_in_world[2] - state.position_base_in_world[2],
                np.degrees((rotation_estimated * rotation_true.inv()).as_rotvec()[2]),
            )
        )
    names = ("time_s", "tilt_deg", "velocity_m_per_s", "height_m", "yaw_deg")
    columns = np.array(rows).reshape(-1, len(names)).T
    return dict(zip(names, columns, strict=True))


def base_estimate_errors(record: RunRecord) -> dict[str, float]:
    """The run's base estimate errors (:func:`base_estimate_error_series`) summed up.

    The largest and RMS tilt error, the velocity error's RMS, the largest height error
    and the yaw error at the end; empty when no tick has an estimate.
    """
    series = base_estimate_error_series(record)
    tilt = series["tilt_deg"]
    if not tilt.size:
        return {}
    return {
        "tilt_error_max_deg": float(tilt.max()),
        "tilt_error_rms_deg": float(np.sqrt(np.mean(tilt**2))),
        "velocity_error_rms_m_per_s": float(np.sqrt(np.mean(series["velocity_m_per_s"] ** 2))),
        "height_error_max_m": float(np.max(np.abs(series["height_m"]))),
        "yaw_error_end_deg": float(series["yaw_deg"][-1]),
    }


def compute_metrics(record: RunRecord) -> dict[str, Any]:
    """The run's report: fall, CM excursion, tracking RMS, COP margin, foot slip, torques, speed.

    Also its ``kind`` (:func:`scenario_kind`), whose summary the table prints (a walk's
    ``walking``, a jump's ``jump``), and the scenario's ``warnings``
    (:func:`~clients.sim.scenario.scenario_warnings`). A run stopped before its first tick
    reports only what it is, its warnings and why it stopped.
    """
    outcome = {
        "scenario": record.scenario.name,
        "kind": scenario_kind(record.scenario),
        "backend": record.scenario.backend,
        "controller": record.scenario.controller,
        "fell": record.fell,
        "fall_time_s": record.fall_time_s,
        "fall_reason": record.fall_reason,
        "complete": not record.stopped,
        "stopped": record.stopped,
        "simulated_s": record.simulated_s,
        "model_notes": record.model_notes,
        "warnings": scenario_warnings(record.scenario),
    }
    if not record.commands:
        return outcome
    diagnostics = record.diagnostics()
    flags_of_diagnosed = [record.contact_flags[tick] for tick in record.diagnosed_ticks()]
    com = np.array([d.position_com_in_world for d in diagnostics])
    torques = np.array([c.joint_torque for c in record.commands])
    limits = np.concatenate([j.torque_limit for j in record.welcome.joints])
    cop_inside = [
        strictly_inside(d.center_of_pressure[:2], d.support_polygon_xy.reshape(-1, 2))
        for d, flags in zip(diagnostics, flags_of_diagnosed, strict=True)
        if any(flags)
    ]
    errors = _joint_errors_rad(record)
    slip_m, rotation_rad = _foot_slip_and_rotation(record)
    estimation = base_estimate_errors(record)
    return {
        **outcome,
        "com_excursion_m": float(np.max(np.linalg.norm(com[:, :2] - com[0, :2], axis=1))),
        "com_start_offset_m": _com_start_offset_m(com[0], diagnostics[0]),
        "tracking_rms_rad": {
            group: float(np.sqrt(np.mean(values**2))) for group, values in sorted(errors.items())
        },
        "cop_strictly_inside_fraction": float(np.mean(cop_inside)) if cop_inside else 0.0,
        "foot_slip_m": slip_m,
        "foot_rotation_rad": rotation_rad,
        "peak_torque_Nm": float(np.abs(torques).max()),
        "peak_torque_fraction_of_limit": float(np.max(np.abs(torques) / limits)),
        "real_time_factor": record.real_time_factor,
        "server_compute_p50_ms": float(
            np.percentile([d.compute_time_s for d in diagnostics], 50) * 1e3
        ),
        **({"base_estimate_error": estimation} if estimation else {}),
        **({"jump": jump_metrics(record)} if asks_behavior(record, "jump") else {}),
        **({"walking": walking_metrics(record)} if asks_behavior(record, "walk") else {}),
    }


START_OFFSET_NOTE_M = 0.01
"""A start pose whose CM is farther than this from the support centre is noted in the summary."""


def _com_start_offset_m(com_in_world: np.ndarray, first: Any) -> list[float]:
    """The CM's ground projection at the first tick minus the support polygon's centroid (x, y).

    The momentum and prioritized controllers hold the CM over the centre of
    support (eq. 5.9's ``s``, plus ``com_offset_xy``); a start pose whose CM is
    elsewhere (a model's upright pose puts it over the ankles, behind the soles'
    centre) moves toward it in the first second of any run, as far as the pose
    objective lets it (4 of the 6 cm on the thesis humanoid), and the CM
    excursion includes that move. The report says how far it starts.
    """
    polygon = np.asarray(first.support_polygon_xy, dtype=float).reshape(-1, 2)
    if len(polygon) < 3:
        return [0.0, 0.0]
    x, y = polygon[:, 0], polygon[:, 1]
    cross = x * np.roll(y, -1) - np.roll(x, -1) * y  # shoelace: area-weighted centroid
    area = cross.sum() / 2
    if abs(area) < 1e-12:
        return [0.0, 0.0]
    centroid = np.array(
        [((x + np.roll(x, -1)) * cross).sum(), ((y + np.roll(y, -1)) * cross).sum()]
    ) / (6 * area)
    return [float(v) for v in com_in_world[:2] - centroid]


def start_pose_note(report: dict[str, Any]) -> str | None:
    """The summary's note on a start pose whose CM is off the support centre, or ``None``."""
    offset = report.get("com_start_offset_m")
    if offset is None or report.get("controller") == "tracking":  # it holds no CM
        return None
    distance = float(np.hypot(*offset))
    if distance <= START_OFFSET_NOTE_M:
        return None
    return (
        f"the start pose puts the CM {distance:.3f} m from the support centre "
        f"(x {offset[0]:+.3f}, y {offset[1]:+.3f} m), toward which the controller's CM "
        "objective pulls it in the first second (the pose objective holds it back part of "
        "the way); CM exc. includes that move"
    )


def _controller_supports(record: RunRecord) -> list[list[bool]]:
    """Per tick, the controller's supports.

    ``diagnostics.supports``, carried over the ticks without diagnostics; the client's flags
    where the record has no commands.
    """
    if not record.commands:
        return [list(flags) for flags in record.contact_flags]
    supports: list[list[bool]] = []
    current = list(record.contact_flags[0])
    for command in record.commands:
        if command.diagnostics is not None:
            current = list(command.diagnostics.supports)
        supports.append(current)
    return supports


SWING_MIN_S = 0.05
"""A contact released at least this long and then supporting again has stepped (shorter
releases are a sole's flicker at touch-down)."""


def touchdowns(
    record: RunRecord, supports: list[list[bool]] | None = None
) -> list[tuple[int, int]]:
    """``(tick, contact)`` of each touch-down.

    A touch-down is a contact that supports again (the controller's supports) after it
    was released for at least :data:`SWING_MIN_S`.
    """
    supports = _controller_supports(record) if supports is None else supports
    released_at: dict[int, float] = {}
    events = []
    for tick, flags in enumerate(supports):
        time_s = record.time_s[tick]
        for contact, on in enumerate(flags):
            if not on:
                released_at.setdefault(contact, time_s)
            elif contact in released_at:
                if time_s - released_at.pop(contact) >= SWING_MIN_S:
                    events.append((tick, contact))
    return events


def scenario_kind(scenario: Scenario) -> str:
    """What the scenario tests: ``"walk"``, ``"jump"`` or ``"balance"``.

    The first behavior of the two it asks for (at start or in a parameter change), else
    ``"balance"``: standing, pushes, motions on the spot.
    """
    for params in [scenario.params, *(change.params for change in scenario.param_changes)]:
        if params.get("behavior") in ("walk", "jump"):
            return str(params["behavior"])
    return "balance"


def asks_behavior(record: RunRecord, behavior: str) -> bool:
    """Whether the scenario asks for ``behavior`` (``"jump"``, ``"walk"``) at start or later."""
    scenario = record.scenario
    return any(
        params.get("behavior") == behavior
        for params in [scenario.params, *(change.params for change in scenario.param_changes)]
    )


def walking_metrics(record: RunRecord) -> dict[str, Any]:
    """A walk's report (issue 19): distance, speed, steps, slip, turn, fall.

    ``distance_m`` is the base's horizontal displacement from the first state to the
    last, ``speed_m_per_s`` the displacement from the first lift-off (the first tick a
    support is released) to the end over the time it took, ``final_speed_m_per_s`` the
    same over the run's last half, ``step_count`` the touch-downs (:func:`touchdowns`),
    ``foot_slip_m`` the largest slide of a sole frame while it supports (as in
    :func:`compute_metrics`), ``turn_deg`` the base's change of heading, ``fell``
    whether it fell.
    """
    if not record.states:
        return {"fell": record.fell, "distance_m": 0.0, "step_count": 0}
    supports = _controller_supports(record)
    start = np.asarray(record.states[0].position_base_in_world[:2])
    end = np.asarray(record.states[-1].position_base_in_world[:2])
    lift = next((tick for tick, flags in enumerate(supports) if not all(flags)), None)
    steps = len(touchdowns(record, supports))
    speed = 0.0
    if lift is not None and record.time_s[-1] > record.time_s[lift]:
        origin = np.asarray(record.states[lift].position_base_in_world[:2])
        speed = float(np.linalg.norm(end - origin)) / (record.time_s[-1] - record.time_s[lift])

    half = len(record.states) // 2
    final_speed = 0.0
    if record.time_s[-1] > record.time_s[half]:
        middle = np.asarray(record.states[half].position_base_in_world[:2])
        final_speed = float(np.linalg.norm(end - middle)) / (
            record.time_s[-1] - record.time_s[half]
        )

    def heading(state: Any) -> float:
        return float(Rotation.from_quat(state.orientation_base_in_world_xyzw).as_euler("ZYX")[0])

    turn = np.degrees(np.unwrap([heading(state) for state in record.states]))
    slip_m, _ = _foot_slip_and_rotation(record)
    return {
        "fell": record.fell,
        "distance_m": float(np.linalg.norm(end - start)),
        "speed_m_per_s": speed,
        "final_speed_m_per_s": final_speed,
        "step_count": steps,
        "foot_slip_m": slip_m,
        "turn_deg": float(turn[-1] - turn[0]),
    }
