"""The one interface every controller implements, and its parameter handling.

The server talks to controllers only through :class:`Controller`: create it
for a robot with initial parameters, ``compute`` one tick, read and change
parameters. Each controller declares its parameters as :class:`ParamSpec`s;
validation (type, range, length, finiteness) is shared here, so every
controller refuses bad values the same way, atomically.

Every controller hosts behaviours the same way (:meth:`Controller._host`): the one its
``behavior`` parameter names observes each tick and answers its
:class:`~controller_server.behaviors.Targets`, whose parameter values hold over the
client's for that tick only (:meth:`Controller.in_force`).

Every controller computes its dynamics terms the same way (:meth:`Controller._dynamics_terms`):
by the compiled core or by the Python specification, as its ``kernel`` parameter says.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import pinocchio as pin

from controller_server.behaviors import BEHAVIORS, Behavior, Observation, Targets
from controller_server.dynamics import (
    KERNELS,
    CompiledDynamics,
    DynamicsTerms,
    compute_dynamics_terms,
)
from controller_server.errors import ControllerFailed, InvalidParams
from controller_server.models import RobotModel
from controller_server.params import ParamSpec
from controller_server.tasks import TaskStack, Tick
from protocol.errors import did_you_mean

__all__ = [
    "CONTACT_PARAMETERS",
    "KERNEL_PARAMETERS",
    "ControlInput",
    "ControlOutput",
    "Controller",
    "ControllerFailed",
    "ParamSpec",
    "check_finite_dynamics",
    "normalized_configuration_part",
    "vector_value",
]


def check_finite_dynamics(terms: DynamicsTerms) -> None:
    """Refuse a state whose velocity terms overflowed (velocities far beyond any robot's).

    Raises:
        ControllerFailed: Naming the non-finite terms and the largest velocity.
    """
    momentum = terms.momentum
    groups = {
        "bias forces": (terms.bias_forces,),
        "contact drifts": (*terms.support_drifts, *terms.point_drifts),
        "momentum": (
            momentum.r_bias,
            momentum.s_bias,
            momentum.linear_momentum,
            momentum.angular_momentum,
        ),
    }
    # One sum over everything first: NaN and ±inf propagate through it (the common case is
    # one reduction); only a non-finite sum (or an overflowing one) looks at each group.
    if math.isfinite(
        float(np.concatenate([a for arrays in groups.values() for a in arrays]).sum())
    ):
        return
    bad = [name for name, arrays in groups.items() if not all(np.isfinite(a).all() for a in arrays)]
    if bad:
        raise ControllerFailed(
            f"non-finite {', '.join(bad)} at this state (max |v| = "
            f"{float(np.max(np.abs(terms.v))):.3g}: the dynamics overflow); no command"
        )


def vector_value(field: str, value: Any, length: int) -> np.ndarray:
    """A list of ``length`` finite numbers as an array, or :class:`InvalidParams`."""
    if not isinstance(value, list | tuple | np.ndarray) or any(
        isinstance(x, bool) or not isinstance(x, int | float | np.floating) for x in value
    ):
        raise InvalidParams(field, f"{value=!r} is not a list of numbers")
    try:
        array = np.asarray(value, dtype=float).reshape(-1)
    except OverflowError:  # a Python int beyond the float range (not printed: it may be huge)
        raise InvalidParams(field, "a value is beyond the float range; must be finite") from None
    if array.size != length:
        raise InvalidParams(field, f"expected {length} values, got {array.size}")
    if not np.all(np.isfinite(array)):
        raise InvalidParams(field, f"{value=!r} must be finite")
    return array


def normalized_configuration_part(
    robot: RobotModel, field: str, values: np.ndarray, part: slice
) -> np.ndarray:
    """``values`` written into ``q[part]``, quaternions (root, ball joints) normalized.

    Raises:
        InvalidParams: A quaternion in ``part`` is (nearly) zero.
    """
    q = pin.neutral(robot.model)
    q[part] = values
    starts = [3, *(7 + robot.ball_quaternion_starts)]
    if any(np.linalg.norm(q[s : s + 4]) < 1e-9 for s in starts):
        raise InvalidParams(field, "quaternions must be non-zero")
    return pin.normalize(robot.model, q)[part]


CONTACT_PARAMETERS: dict[str, ParamSpec] = {
    "ground_height": ParamSpec(0.0, minimum=-1e3, maximum=1e3, doc="ground plane z (m)"),
    "friction_coefficients": ParamSpec(
        None,
        kind="vector",
        minimum=0.0,
        maximum=10.0,
        doc="Coulomb μ per contact (welcome order); default the model's contacts' μ",
    ),
    "support_mask": ParamSpec(
        None,
        kind="vector",
        minimum=0.0,
        maximum=1.0,
        doc="per contact (welcome order), 0 = never a support even when touching "
        "(lift a foot: single-support motions); default all 1",
    ),
}
"""The ground and the contacts, the same for every controller."""

KERNEL_PARAMETERS: dict[str, ParamSpec] = {
    "kernel": ParamSpec(
        "compiled",
        kind="choice",
        choices=KERNELS,
        doc="the compiled core or the Python specification: the weighted controllers' whole "
        "tick (dynamics, optimizer, inverse dynamics; controllers/compiled_tick.py), the "
        "prioritized controller's dynamics terms, the IMU path's estimator; equal to rounding "
        "(tests/controller_server/test_compiled_*.py)",
    ),
}
"""Which implementation runs a controller's tick: the compiled core or the Python."""


@dataclass(frozen=True)
class ControlInput:
    """One tick's state, in Pinocchio's conventions.

    Attributes:
        time_s: Client time (s).
        q: Configuration ``[p_base, quat_xyzw, q_joints]``, ``(nq,)``.
        v: Velocity ``[v_base_in_base, ω_base_in_base, v_joints]``, ``(nv,)``.
        contact_flags: One flag per contact of the robot.
        contact_wrench_in_world: ``(contacts, 6)`` measured ground wrenches, if sent.
        want_diagnostics: Whether this tick's diagnostics will be sent; a
            controller may skip computing them when not.
    """

    time_s: float
    q: np.ndarray
    v: np.ndarray
    contact_flags: tuple[bool, ...]
    contact_wrench_in_world: np.ndarray | None = None
    want_diagnostics: bool = True


@dataclass(frozen=True)
class ControlOutput:
    """One tick's result, in Pinocchio's conventions.

    Attributes:
        acceleration: ``(nv,)`` generalized acceleration.
        joint_torque: ``(nv − 6,)`` actuated torques.
        contact_force_in_world: ``(p, 3)`` per contact point (N).
        contact_wrench_in_world: ``(contacts, 6)`` per contact (N, N·m).
        diagnostics: Wire diagnostics of this tick except the compute time
            (see :class:`protocol.Diagnostics`), or ``None`` when not wanted.
    """

    acceleration: np.ndarray
    joint_torque: np.ndarray
    contact_force_in_world: np.ndarray
    contact_wrench_in_world: np.ndarray
    diagnostics: dict[str, Any] | None


class Controller(ABC):
    """A whole-body controller for one robot (one per session).

    A subclass fills :attr:`tasks` before calling ``super().__init__``; the base keeps the
    tasks' weights and levels equal to the parameters in force (:meth:`_tick`) and has them
    forget what they derived whenever those parameters change.
    """

    name: ClassVar[str]
    PARAMETERS: ClassVar[dict[str, ParamSpec]]
    tasks: TaskStack
    """The controller's objectives by name, with their weights and levels."""

    def __init__(self, robot: RobotModel, params: Mapping[str, Any] | None = None):
        self.robot = robot
        self._data = robot.model.createData()
        """This session's Pinocchio data: after :meth:`_dynamics_terms`, the state's kinematics."""
        self._compiled: CompiledDynamics | None = None  # the compiled core, at its first tick
        self.gravity = float(np.linalg.norm(robot.model.gravity.linear))
        """``‖g‖`` of the model (m/s²)."""
        self._behavior: Behavior | None = None
        self._overrides: dict[str, Any] = {}  # the behaviour's parameters, validated
        self._override_revision = -1
        self._in_force: dict[str, Any] | None = None  # the client's, the behaviour's over them
        self._params: dict[str, Any] = {key: self.default_value(key) for key in self.PARAMETERS}
        self.set_params(params or {})

    def default_value(self, key: str) -> Any:
        """Default of a parameter; model-dependent ones are derived from the robot.

        Shared model-dependent defaults: the standing pose's joints and base
        orientation (the keyframe's, or the file's) for
        ``reference_joint_position`` and the reference base (trunk)
        orientation, all ones for ``support_mask``, the model's μ for
        ``friction_coefficients``. Override for others.
        """
        robot = self.robot
        if key == "reference_joint_position":
            return robot.standing_joint_position.copy()
        if key in ("reference_base_orientation_xyzw", "reference_trunk_orientation_xyzw"):
            return robot.standing_orientation_base_in_world_xyzw.copy()
        if key == "support_mask":
            return np.ones(len(robot.contacts))
        if key == "friction_coefficients":
            return np.array([c.friction_coefficient for c in robot.contacts])
        return self.PARAMETERS[key].default

    def parameters(self) -> dict[str, Any]:
        """Every parameter in force, as wire values (floats, strings, lists)."""
        return {
            key: [float(x) for x in value] if isinstance(value, np.ndarray) else value
            for key, value in self._params.items()
        }

    def set_params(self, params: Mapping[str, Any]) -> None:
        """Validate all of ``params``, then apply them together (all or nothing).

        Raises:
            InvalidParams: Naming the first bad key and why.
        """
        validated = {key: self._validate(key, value) for key, value in params.items()}
        self._check_together({**self._params, **validated})
        self._params.update(validated)
        self._in_force = None
        self.tasks.reset()
        if "behavior" in params:  # ends the behaviour under way: the next tick starts anew
            self._behavior, self._overrides, self._override_revision = None, {}, -1

    def _check_together(self, params: Mapping[str, Any]) -> None:  # noqa: B027 (a hook)
        """Refuse values that are valid one by one but not together (before any applies).

        Raises:
            InvalidParams: Naming the key to change and why.
        """

    def _validate(self, key: str, value: Any) -> Any:
        spec = self.PARAMETERS.get(key)
        field = f"params.{key}"
        if spec is None:
            hint = did_you_mean(key, self.PARAMETERS)
            raise InvalidParams(
                field, f"unknown parameter; {hint}known: {', '.join(self.PARAMETERS)}"
            )
        if spec.kind == "choice":
            if value not in spec.choices:
                raise InvalidParams(field, f"{value=!r}; choose one of {spec.choices}")
            if key == "behavior" and value in BEHAVIORS and self.name not in BEHAVIORS[value].HOSTS:
                hosts = ", ".join(BEHAVIORS[value].HOSTS)
                raise InvalidParams(
                    field,
                    f"{value!r} cannot run on the {self.name} controller; it runs on {hosts}",
                )
            return value
        if spec.kind == "text":
            if not isinstance(value, str):
                raise InvalidParams(field, f"{value=!r} is not a string")
            return value
        if spec.kind == "bool":
            if not isinstance(value, bool):
                raise InvalidParams(field, f"{value=!r} is not true or false")
            return value
        if spec.kind in ("float", "int"):
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise InvalidParams(field, f"{value=!r} is not a number")
            # Finite first: int() of inf or NaN would raise; a huge int overflows float().
            try:
                number = float(value)
            except OverflowError:
                raise InvalidParams(field, "value beyond the float range; must be finite") from None
            if not math.isfinite(number):
                raise InvalidParams(field, f"{value=!r} must be finite")
            if spec.kind == "int" and number != math.floor(number):
                raise InvalidParams(field, f"{value=!r} is not an integer")
            array = np.array([number])
        else:
            array = vector_value(field, value, np.size(self.default_value(key)))
        if not np.all(np.isfinite(array)):
            raise InvalidParams(field, f"{value=!r} must be finite")
        if np.any(array < spec.minimum) or np.any(array > spec.maximum):
            raise InvalidParams(field, f"{value=!r} outside [{spec.minimum}, {spec.maximum}]")
        if spec.kind == "int":
            return int(array[0])
        return float(array[0]) if spec.kind == "float" else array

    def in_force(self) -> dict[str, Any]:
        """The parameters of this tick: the client's, and the behaviour's over them."""
        if self._in_force is None:
            self._in_force = {**self._params, **self._overrides}
        return self._in_force

    @property
    def behavior_state(self) -> str:
        """``balance``, or the state of the behaviour under way (``stand``, ``compress`` …)."""
        return "balance" if self._behavior is None else self._behavior.state

    def _host(
        self, control_input: ControlInput, observe: Callable[[], Observation]
    ) -> Targets | None:
        """Run the behaviour ``behavior`` names for this tick (``None``: none, or ``balance``).

        It is created at its first tick; its parameter values are validated as a
        ``set_params`` would validate them (once per revision), and hold over the client's in
        :meth:`in_force` until it changes them. ``observe`` gives what it observes of the
        state (:meth:`_observation`, or the compiled tick's), called only when a behaviour runs.

        Raises:
            InvalidParams: The behaviour set a value its host refuses.
        """
        name = self._params.get("behavior", "balance")
        if name == "balance":
            return None
        if self._behavior is None:
            self._behavior = BEHAVIORS[name](self.robot)
        targets = self._behavior.update(observe(), self.in_force())
        if targets.revision != self._override_revision:
            self._overrides = {key: self._validate(key, v) for key, v in targets.params.items()}
            self._override_revision = targets.revision
            self._in_force = None
            self.tasks.reset()
            self._overrides_changed()
        return targets

    def _observation(self, control_input: ControlInput, terms: DynamicsTerms) -> Observation:
        """What a behaviour observes: the state, its terms, frame placements of ``self._data``."""
        return self.observation(
            control_input,
            position_com_in_world=terms.position_com_in_world,
            velocity_com_in_world=terms.momentum.linear_momentum / terms.total_mass,
            position_contact_frames_in_world=terms.position_contact_frames_in_world,
            orientation_contact_frames_in_world=np.array(
                [self._data.oMf[c.frame_id].rotation for c in self.robot.contacts]
            ),
        )

    def observation(
        self,
        control_input: ControlInput,
        *,
        position_com_in_world: np.ndarray,
        velocity_com_in_world: np.ndarray,
        position_contact_frames_in_world: np.ndarray,
        orientation_contact_frames_in_world: np.ndarray,
    ) -> Observation:
        """A behaviour's :class:`Observation` of the state and these quantities of it."""
        return Observation(
            time_s=control_input.time_s,
            position_com_in_world=position_com_in_world,
            velocity_com_in_world=velocity_com_in_world,
            touching=control_input.contact_flags,
            position_contact_frames_in_world=position_contact_frames_in_world,
            joint_position=control_input.q[7:],
            orientation_base_in_world_xyzw=control_input.q[3:7],
            orientation_contact_frames_in_world=orientation_contact_frames_in_world,
            ground_height=self._params["ground_height"],
        )

    def _dynamics_terms(self, control_input: ControlInput) -> DynamicsTerms:
        """The state's dynamics terms by the ``kernel`` in force (Python by default, for now).

        Either way ``self._data`` is left with the state's kinematics (frame placements, joint
        Jacobians, velocities and accelerations at ``q̈ = 0``), which behaviours and tasks read.

        Raises:
            CompiledCoreUnavailable: ``kernel`` is ``"compiled"`` and the core is not built (or
                was built for another Pinocchio); never a silent fall back to Python.
        """
        q, v = control_input.q, control_input.v
        if self.in_force()["kernel"] == "python":
            return compute_dynamics_terms(self.robot, self._data, q, v)
        if self._compiled is None:
            self._compiled = CompiledDynamics(self.robot)
        return self._compiled.compute(self._data, q, v)

    def _tick(
        self,
        control_input: ControlInput,
        terms: DynamicsTerms,
        flags: tuple[bool, ...],
        **context: Any,
    ) -> Tick:
        """What the stack's tasks read this tick, with the parameters in force.

        The tasks' weights and levels follow those parameters first (``weight_<name>``,
        ``priority_<name>``). ``context``: the controller's own fields of
        :class:`~controller_server.tasks.Tick` (a behaviour's targets, the sole points, the
        support polygon, the ground wrenches).
        """
        params = self.in_force()
        self.tasks.follow(params)
        return Tick(
            robot=self.robot,
            data=self._data,
            q=control_input.q,
            v=control_input.v,
            time_s=control_input.time_s,
            terms=terms,
            params=params,
            supports=flags,
            gravity=self.gravity,
            **context,
        )

    def _overrides_changed(self) -> None:  # noqa: B027 (a hook: most controllers derive nothing)
        """Called when the behaviour's parameter values change (drop what was derived)."""

    def supports(self, control_input: ControlInput) -> tuple[bool, ...]:
        """Contacts used as supports: flagged by the client and allowed by ``support_mask``."""
        return tuple(
            bool(on and allowed > 0.5)
            for on, allowed in zip(
                control_input.contact_flags, self.in_force()["support_mask"], strict=True
            )
        )

    @abstractmethod
    def compute(self, control_input: ControlInput) -> ControlOutput:
        """Accelerations and torques for one tick."""
