"""Scenario files: what to simulate, validated by pydantic.

A scenario is a TOML file naming the model, the controller and its
parameters, the backend, friction, duration, control and physics rates,
the initial pose, the pushes and timed parameter changes (a motion clip
starting, a weight shift, a foot leaving the supports, point targets
dragged). Built-in scenarios (thesis ch. 7) live in
``clients/sim/scenarios/`` and load by name.

A built-in scenario runs on any biped (``--model``), so it says what it
needs in the robot's terms (:mod:`clients.physics.robot_terms`): a crouch as a
knee bend (``initial_knee_bend_rad``), pushes on ``trunk`` or ``root`` (or
``chest``, ``torso``, ``abdomen``, ``pelvis`` on a robot without a body of
that name), a twist as a yaw rate (``twist_yaw_rate_rad_per_s``), turned
into each robot's joints, bodies and angular momentum when it loads.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from clients.explain import explain
from clients.physics.backend import PushSpec
from clients.physics.errors import ScenarioError, ScenarioNotFound
from clients.physics.imu import ImuSpec
from clients.physics.model_file import DescriptionError, body_names, describe_model
from clients.physics.robot_terms import (
    RobotTermsError,
    crouched_joint_positions,
    resolve_body,
    vertical_inertia,
)
from protocol.errors import did_you_mean
from protocol.messages import ContactSpec

__all__ = [
    "SCENARIO_DIR",
    "ParamChange",
    "Scenario",
    "builtin_scenario_names",
    "controller_params",
    "initial_configuration",
    "initial_joint_positions",
    "load_scenario",
    "scenario_warnings",
]

SCENARIO_DIR = Path(__file__).parent / "scenarios"


class ParamChange(BaseModel):
    """Controller parameters sent (``set_params``) at the first control tick at or after a time."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    time_s: float = Field(ge=0.0, description="When (s of simulated time).")
    params: dict[str, Any] = Field(description="Parameters to set, as in `set_params`.")


class Scenario(BaseModel):
    """One simulated run."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str = Field(description="Scenario name (report and plot titles).")
    description: str = Field(default="", description="What it shows.")
    model: str = Field(
        default="thesis_humanoid",
        description="Built-in model, or an MJCF (a scene with includes is fine) or URDF path.",
    )
    keyframe: str | None = Field(
        default=None,
        description="MJCF keyframe of the standing pose: the initial joints and base pose, the "
        "controller's reference pose and CM height (default: the file's pose).",
    )
    contacts: list[ContactSpec] | None = Field(
        default=None,
        description="The feet, as in `hello.contacts`: tables with `name` and `frame` (a body "
        "or site), and `points_in_frame` to give the sole yourself; without points the sole is "
        "found from the body's collision geometry. Default: found automatically.",
    )
    controller: str = Field(default="momentum", description="Server controller.")
    params: dict[str, Any] = Field(default_factory=dict, description="Controller parameters.")
    backend: Literal["reference", "mujoco"] = Field(default="reference")
    friction_coefficient: float = Field(default=0.8, gt=0.0, le=5.0)
    mujoco_contact_time_constant_s: float | None = Field(
        default=None,
        gt=0.0,
        le=1.0,
        description="MuJoCo only: time constant of the floor's contacts (s; `solref`, damping "
        "ratio 1), at least two physics steps. Default: the model's (MuJoCo's 0.02 s, soft: a "
        "standing thesis humanoid sinks 1.1 mm, and a sole loaded at its edge rolls on it). "
        "The reference simulator's penalty contact ignores it.",
    )
    duration_s: float = Field(default=3.0, gt=0.0, le=600.0)
    control_rate_hz: float = Field(default=1000.0, gt=0.0, le=10_000.0)
    physics_rate_hz: float = Field(default=1000.0, gt=0.0, le=100_000.0)
    command_delay_ticks: Literal[0, 1] = Field(
        default=0,
        description="0: lockstep, each state's command drives the physics from that tick. "
        "1: pipelined, the command for the state of tick k drives the physics from tick k + 1, "
        "and the simulator steps while the server computes (one control period of latency, as "
        "between sensing and actuation on hardware); the state sent is then the one predicted "
        "for tick k + 1 with the accelerations of the command acting meanwhile.",
    )
    diagnostics_period_ticks: int = Field(
        default=1,
        ge=1,
        le=1000,
        description="Diagnostics with every N-th command (hello.diagnostics_period_ticks); "
        "the metrics and plots use the ticks that have them.",
    )
    ground_force_mode: Literal["distributed", "measured"] = Field(default="distributed")
    support_force_threshold_N: float = Field(
        default=20.0,
        ge=0.0,
        description="A touching foot becomes a support once its normal force exceeds this (N); "
        "it stays one until it lifts off.",
    )
    base_state: Literal["truth", "imu"] = Field(
        default="truth",
        description="How the client gives the base: `truth`, the simulator's base pose and "
        "twist; `imu`, the readings of a simulated IMU (the `imu` table), from which the server "
        "estimates the base (its contact-aided EKF: docs/estimation.md).",
    )
    imu: ImuSpec = Field(
        default_factory=ImuSpec,
        description='The simulated IMU of `base_state = "imu"`: mounting and errors '
        "(BMI088 defaults); it samples once per control tick.",
    )
    initial_knee_bend_rad: float | None = Field(
        default=None,
        ge=0.0,
        le=2.0,
        description="At t = 0 each knee bent to at least this angle between thigh and shank "
        "(rad), its hip and ankle pitch turned half as much the other way (feet flat, trunk "
        "upright): the legs are found from the robot (the joints from the root to each "
        "contact), so it carries to any biped; `initial_joint_position` overrides it joint "
        "by joint. Default: the standing pose's legs.",
    )
    initial_joint_position: dict[str, list[float]] = Field(
        default_factory=dict, description="Joint name → position (rad; ball: xyzw) at t = 0."
    )
    twist_yaw_rate_rad_per_s: float | None = Field(
        default=None,
        ge=-50.0,
        le=50.0,
        description="A jump's twist as the yaw rate the thrust gives the whole robot (rad/s): "
        "sent as the `jump_twist_angular_momentum` parameter, this × the robot's vertical "
        "inertia (composite rigid body, about its CM) at its starting pose (kg·m²/s), so a "
        "lighter robot gets less. Default: the parameters' own.",
    )
    pushes: list[PushSpec] = Field(default_factory=list)
    param_changes: list[ParamChange] = Field(
        default_factory=list, description="Run-time parameter changes, in time order."
    )

    @model_validator(mode="after")
    def _rates(self) -> Scenario:
        ratio = self.physics_rate_hz / self.control_rate_hz
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError(
                f"physics_rate_hz ({self.physics_rate_hz}) must be a whole multiple of "
                f"control_rate_hz ({self.control_rate_hz})"
            )
        contact = self.mujoco_contact_time_constant_s
        if contact is not None and contact * self.physics_rate_hz < 2.0 - 1e-9:
            raise ValueError(
                f"mujoco_contact_time_constant_s ({contact}) must be at least two physics steps "
                f"({2.0 / self.physics_rate_hz} s at physics_rate_hz {self.physics_rate_hz})"
            )
        return self

    @model_validator(mode="after")
    def _imu(self) -> Scenario:
        if "rate_hz" in self.imu.model_fields_set and self.imu.rate_hz != self.control_rate_hz:
            raise ValueError(
                f"imu.rate_hz ({self.imu.rate_hz:g}) must equal control_rate_hz "
                f"({self.control_rate_hz:g}), one sample per state; or leave it out"
            )
        if self.base_state == "imu" and self.command_delay_ticks:
            raise ValueError(
                'base_state = "imu" needs command_delay_ticks = 0: a delayed command is '
                "computed for a predicted state, which needs the base the server estimates"
            )
        return self

    @model_validator(mode="after")
    def _one_twist(self) -> Scenario:
        if self.twist_yaw_rate_rad_per_s is not None and "jump_twist_angular_momentum" in (
            self.params
        ):
            raise ValueError(
                "give twist_yaw_rate_rad_per_s or params.jump_twist_angular_momentum, not both"
            )
        return self

    @model_validator(mode="after")
    def _changes_in_order(self) -> Scenario:
        times = [change.time_s for change in self.param_changes]
        if times != sorted(times):
            raise ValueError(f"param_changes must be in time order, got times {times}")
        return self

    @property
    def physics_steps_per_control_tick(self) -> int:
        """Physics steps between two control ticks (zero-order hold of the torques)."""
        return round(self.physics_rate_hz / self.control_rate_hz)


def builtin_scenario_names() -> list[str]:
    """Names of the built-in scenarios, sorted."""
    return sorted(path.stem for path in SCENARIO_DIR.glob("*.toml"))


def load_scenario(name_or_path: str | Path, **overrides: Any) -> Scenario:
    """Load a scenario by built-in name or TOML path, with field overrides.

    Raises:
        ScenarioNotFound: No such built-in or file (the message lists the built-ins).
        ScenarioError: The file is not TOML, has an unknown key (the message
            suggests the closest known one), a value of the wrong type or
            range, or names a model that does not exist.
    """
    path = Path(name_or_path)
    if not path.suffix:
        path = SCENARIO_DIR / f"{name_or_path}.toml"
    if not path.is_file():
        raise ScenarioNotFound(
            f"no scenario {str(name_or_path)!r}: no such file, and built in are "
            f"{', '.join(builtin_scenario_names())}"
        )
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"scenario {str(name_or_path)!r} is not valid TOML: {exc}") from exc
    data.update(overrides)
    try:
        scenario = Scenario.model_validate(data)
    except ValidationError as exc:
        raise ScenarioError(f"scenario {str(name_or_path)!r}: {explain(exc, Scenario)}") from exc
    try:
        describe_model(scenario.model, contacts=scenario.contacts, keyframe=scenario.keyframe)
    except FileNotFoundError as exc:
        raise ScenarioError(f"scenario {str(name_or_path)!r}: {exc}") from exc
    except DescriptionError as exc:
        key = {"model": "model", "contacts": "contacts", "keyframe": "keyframe"}[exc.field]
        raise ScenarioError(f"scenario {str(name_or_path)!r}: {key}: {exc}") from None
    bodies = body_names(scenario.model)
    scenario = _resolve_push_bodies(str(name_or_path), scenario, bodies)
    _check_initial_pose(str(name_or_path), scenario)
    if scenario.imu.body and bodies and scenario.imu.body not in bodies:
        hint = did_you_mean(scenario.imu.body, bodies)
        raise ScenarioError(
            f"scenario {str(name_or_path)!r}: imu.body: {scenario.model} has no body "
            f"{scenario.imu.body!r}; {hint}bodies: {', '.join(bodies)}"
        )
    return scenario


def scenario_warnings(scenario: Scenario) -> list[str]:
    """What in ``scenario`` runs but does not test what it seems to, one sentence each.

    A push that starts at or after the run's end (``duration_s``, e.g. shortened with
    ``--duration``) is never applied; a robot with fewer than two contacts (a URDF in which
    one foot was found) stands on one foot, so staying up is not a biped's balance. Neither
    stops the run: the summary and the report say so.
    """
    warnings = []
    late = [
        f"pushes[{index}] at {push.start_s:g} s"
        for index, push in enumerate(scenario.pushes)
        if push.start_s >= scenario.duration_s - 1e-9
    ]
    if late:
        warnings.append(
            f"push{'es' if len(late) > 1 else ''} never applied, starting at or after the "
            f"run's end ({scenario.duration_s:g} s): {', '.join(late)}; lengthen duration_s "
            "(--duration)"
        )
    contacts = describe_model(
        scenario.model, contacts=scenario.contacts, keyframe=scenario.keyframe
    ).contacts
    if len(contacts) < 2:
        warnings.append(
            f"{scenario.model} has {len(contacts)} contact "
            f"({', '.join(contact.name for contact in contacts)}): not a biped on two feet, so "
            "staying up says little of its balance; name both feet (contacts, --contacts)"
        )
    return warnings


def _resolve_push_bodies(name: str, scenario: Scenario, bodies: list[str]) -> Scenario:
    """Pushes on the robot's own bodies (``trunk``, ``root`` …); refused now if it lacks one."""
    description = describe_model(
        scenario.model, contacts=scenario.contacts, keyframe=scenario.keyframe
    )
    pushes = []
    for index, push in enumerate(scenario.pushes):
        body = resolve_body(description, push.body) if bodies else push.body
        if body is None:
            hint = did_you_mean(push.body, bodies)
            raise ScenarioError(
                f"scenario {name!r}: pushes[{index}].body: {scenario.model} has no body "
                f"{push.body!r}; {hint}bodies: {', '.join(bodies)} (or `trunk`, `root`)"
            )
        pushes.append(push if body == push.body else push.model_copy(update={"body": body}))
    return scenario.model_copy(update={"pushes": pushes}) if scenario.pushes else scenario


def _check_initial_pose(name: str, scenario: Scenario) -> None:
    """Refuse now a joint the robot lacks, or a crouch whose legs cannot be found."""
    joints = describe_model(
        scenario.model, contacts=scenario.contacts, keyframe=scenario.keyframe
    ).joint_names
    for joint in scenario.initial_joint_position:
        if joint not in joints:
            hint = did_you_mean(joint, joints)
            raise ScenarioError(
                f"scenario {name!r}: initial_joint_position: {scenario.model} has no joint "
                f"{joint!r}; {hint}joints: {', '.join(joints)}"
            )
    try:
        initial_joint_positions(scenario)
    except RobotTermsError as exc:
        raise ScenarioError(
            f"scenario {name!r}: initial_knee_bend_rad on {scenario.model}: {exc}"
        ) from None


def initial_joint_positions(scenario: Scenario) -> dict[str, list[float]]:
    """The joints set at t = 0, by name.

    The crouch (``initial_knee_bend_rad``), then ``initial_joint_position``.

    Raises:
        RobotTermsError: A crouch on a robot whose legs cannot be found.
    """
    positions: dict[str, list[float]] = {}
    if scenario.initial_knee_bend_rad is not None:
        description = describe_model(
            scenario.model, contacts=scenario.contacts, keyframe=scenario.keyframe
        )
        positions.update(crouched_joint_positions(description, scenario.initial_knee_bend_rad))
    positions.update(scenario.initial_joint_position)
    return positions


def initial_configuration(scenario: Scenario) -> Any:
    """Pinocchio ``q`` at t = 0: the standing pose with :func:`initial_joint_positions`.

    The base is where the standing pose has it (heights are to be measured from the soles).
    """
    description = describe_model(
        scenario.model, contacts=scenario.contacts, keyframe=scenario.keyframe
    )
    q = description.standing_configuration.copy()
    model = description.model
    for joint, value in initial_joint_positions(scenario).items():
        index = model.joints[model.getJointId(joint)].idx_q
        q[index : index + len(value)] = value
    return q


def controller_params(scenario: Scenario) -> dict[str, Any]:
    """The controller parameters sent at ``hello``.

    ``params``, with the twist's yaw rate (``twist_yaw_rate_rad_per_s``) made this robot's
    ``jump_twist_angular_momentum``: × its vertical inertia at :func:`initial_configuration`.
    """
    params = dict(scenario.params)
    if scenario.twist_yaw_rate_rad_per_s is not None:
        description = describe_model(
            scenario.model, contacts=scenario.contacts, keyframe=scenario.keyframe
        )
        params["jump_twist_angular_momentum"] = scenario.twist_yaw_rate_rad_per_s * (
            vertical_inertia(description, initial_configuration(scenario))
        )
    return params
