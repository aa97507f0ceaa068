"""Poise's `momentum` tick against TSID's, on the same robot and states, in one run.

TSID (Del Prete et al., the C++ task-space inverse dynamics library with
Python bindings, PyPI ``tsid``) and Poise's `momentum` controller answer the
same seeded states near standing (random pose, velocities and base tilt, both
feet flagged as supports), each stateless per tick, in alternating chunks so
that both see the same machine load. Also timed on the same states, the floor
of bench/controller.py: Pinocchio's `computeAllTerms` plus the centroidal map
plus one direct DAQP solve of the size of Poise's problem (nv unknowns, 12
support equalities). The script prints the p50 and p99 of each tick, their
ratios to the floor and to TSID, and a sanity check: the p50 of the total
normal ground force each side commands, next to the robot's weight.

The two problems, made as close as the libraries allow (gains and weights
are read from Poise's defaults):

* Poise (`optimizer_period_ticks = 1`, no diagnostics): tracking of the
  neutral pose on every joint and the root orientation (k_s, k_d, weight 1),
  horizontal linear momentum toward the support centre (β_bl = 10, limited
  to what the support polygon and friction admit), angular momentum damped
  (Ḣ_des = −k_H H, weight β_ba = γ ‖p − g‖ from the previous tick's wrenches),
  soft joint limits, both soles as 6-D support equalities (J q̈ = −J̇ q̇),
  solved in closed form, then contact forces with friction pyramids and
  torque limits by one DAQP solve, and the joint torques.
* TSID (`InverseDynamicsFormulationAccForce`, `SolverHQuadProgFast`, one
  weighted level over q̈ and the contact forces): two `Contact6d` with the
  same sole corners and μ, Kp = Kd = 0 (so J q̈ = −J̇ q̇ as Poise's), force
  regularization 1e-5; `TaskJointPosture` toward the same neutral pose and a
  `TaskSE3Equality` on the root orientation (both k_s, k_d, weight 1);
  `TaskComEquality` on x, y toward the support centre and its velocity as
  Poise computes them per state (momentum k_s, k_d, weight β_bl: both sides'
  rows are CM accelerations); `TaskAMEquality` with Ḣ_des = −k_H H at a fixed
  weight 1/m² (Poise's β_ba = 1 in its units); `TaskActuationBounds` at the
  torque limits. Not in TSID's problem: Poise's admissible-momentum limit,
  its varying β_ba, soft joint limits and damped least squares.

Robots: `revolute_humanoid` (built in, the default: TSID's posture task needs
1-DoF joints, so not `thesis_humanoid` or `dino_biped`) or `talos` (PAL
Talos, `talos_reduced.urdf` of PyPI `example-robot-data` installed beside
TSID, nv = 38, soles 0.21 × 0.138 m). Both sides build the robot from the
same file with their own Pinocchio, and the run stops if their mass matrices
or CM positions differ at the first state.

TSID runs in its own interpreter, in a worker process fed by pipes: its
wheels are built against their own Pinocchio, Boost and urdfdom, which need
not (and on Python 3.11 today cannot) be the project's. The interpreter is
``--tsid-python``, else ``$POISE_TSID_PYTHON``, else this one if it has
``tsid``; without any, the script says so and measures Poise and the floor
only. A TSID venv that works (docs/benchmarks.md, "TSID side by side")::

    python3 -m venv ~/.venvs/poise-tsid
    ~/.venvs/poise-tsid/bin/pip install tsid==1.7.1 pin==3.4.0 coal-library==3.0.1 \\
        "cmeel-boost~=1.87.0" "cmeel-urdfdom<5" "cmeel-tinyxml2<11"
    ~/.venvs/poise-tsid/bin/pip install --no-deps example-robot-data==4.3.0  # for talos
    .venv/bin/python bench/tsid_compare.py --tsid-python ~/.venvs/poise-tsid/bin/python

Usage: python bench/tsid_compare.py [--model revolute_humanoid|talos] [--ticks 600]
[--chunks 3] [--tsid-python PATH]
"""

from __future__ import annotations

try:  # TSID's interpreter, which runs the worker, has none of the project
    from controller_server.blas import default_to_single_threaded_blas
except ImportError:
    pass
else:
    default_to_single_threaded_blas()  # before numpy: see controller_server/blas.py

import argparse
import json
import os
import subprocess
import sys
import time
from importlib.util import find_spec
from typing import Any

import numpy as np
import pinocchio as pin

TSID_PYTHON_VARIABLE = "POISE_TSID_PYTHON"
WORKER_FLAG = "--tsid-worker"
WORKER_ENVIRONMENT = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
TALOS_URDF = "talos_data/robots/talos_reduced.urdf"
TALOS_SOLES = {"left_foot": "left_sole_link", "right_foot": "right_sole_link"}
# Sole corners (m) in the sole frames, as in TSID's Talos demos (lxp, lxn, lyp, lyn).
TALOS_SOLE_CORNERS = [(x, y, 0.0) for x in (0.10, -0.11) for y in (0.069, -0.069)]
TSID_FORCE_REGULARIZATION = 1e-5
TSID_MAX_NORMAL_FORCE_N = 1e4
POISE_GAINS = (
    "stiffness",
    "damping",
    "weight_tracking",
    "weight_root_orientation",
    "weight_linear_momentum",
    "momentum_stiffness",
    "momentum_damping",
    "angular_momentum_damping",
)
"""The `momentum` controller's parameters that TSID's tasks take over."""


# TSID's side, in TSID's interpreter -------------------------------------------------------


def import_tsid() -> Any:
    """The ``tsid`` bindings, also from 1.7.1's wheel, whose ``__init__.py`` sits a folder deep."""
    import tsid

    if not hasattr(tsid, "RobotWrapper"):
        # tsid 1.7.1 (cp311) ships tsid/tsid/__init__.py beside tsid/tsid_pywrap*.so, so
        # `import tsid` finds a namespace package; the bindings themselves load fine.
        from tsid import tsid_pywrap as tsid
    return tsid


def build_pinocchio_model(path: str, model_format: str) -> pin.Model:
    """The model as Poise's loader builds it: free-flyer root, root placement at identity."""
    if model_format == "urdf":
        model = pin.buildModelFromUrdf(path, pin.JointModelFreeFlyer())
    else:
        model = pin.buildModelFromMJCF(path)
        if model.njoints < 2 or model.joints[1].shortname() != "JointModelFreeFlyer":
            model, _ = pin.buildModelAndLegacyConstraintsFromMJCF(
                path, pin.JointModelFreeFlyer(), "root"
            )
    model.jointPlacements[1] = pin.SE3.Identity()
    return model


class TsidStanding:
    """TSID's standing problem (see the module docstring), built once and solved per state."""

    def __init__(self, setup: dict[str, Any]):
        tsid = import_tsid()
        self.model = model = build_pinocchio_model(setup["model_path"], setup["model_format"])
        robot = tsid.RobotWrapper(model, tsid.FLOATING_BASE_SYSTEM, False)
        self.formulation = formulation = tsid.InverseDynamicsFormulationAccForce(
            "poise-compare", robot, False
        )
        q = np.array(setup["check_q"])
        formulation.computeProblemData(0.0, q, np.zeros(model.nv))
        data = formulation.data()
        gains = setup["gains"]
        # TSID's C++ side keeps references to these Python objects: they must outlive it.
        self.tasks: list[Any] = [robot]
        for frame, corners, mu in zip(
            setup["contact_frames"], setup["contact_points"], setup["friction"], strict=True
        ):
            contact = tsid.Contact6d(
                f"contact_{frame}",
                robot,
                frame,
                np.asfortranarray(np.array(corners, dtype=float).T),
                np.array([0.0, 0.0, 1.0]),
                mu,
                0.0,
                TSID_MAX_NORMAL_FORCE_N,
            )
            contact.setKp(np.zeros(6))  # J q̈ = −J̇ q̇, as Poise's support equalities
            contact.setKd(np.zeros(6))
            contact.setReference(robot.framePosition(data, model.getFrameId(frame)))
            formulation.addRigidContact(contact, TSID_FORCE_REGULARIZATION)
            self.tasks.append(contact)

        posture = tsid.TaskJointPosture("posture", robot)
        posture.setKp(gains["stiffness"] * np.ones(robot.na))
        posture.setKd(gains["damping"] * np.ones(robot.na))
        posture_reference = tsid.TrajectorySample(robot.na)
        posture_reference.value(np.array(setup["reference_joint_position"]))
        posture.setReference(posture_reference)
        formulation.addMotionTask(posture, gains["weight_tracking"], 1, 0.0)

        orientation = tsid.TaskSE3Equality("root_orientation", robot, model.names[1])
        orientation.setKp(gains["stiffness"] * np.ones(6))
        orientation.setKd(gains["damping"] * np.ones(6))
        orientation.setMask(np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0]))
        orientation.setReference(
            tsid.TrajectorySE3Constant("root", pin.SE3.Identity()).computeNext()
        )
        formulation.addMotionTask(orientation, gains["weight_root_orientation"], 1, 0.0)

        self.com = tsid.TaskComEquality("com", robot)
        self.com.setKp(gains["momentum_stiffness"] * np.ones(3))
        self.com.setKd(gains["momentum_damping"] * np.ones(3))
        self.com.setMask(np.array([1.0, 1.0, 0.0]))
        self.com_reference = tsid.TrajectorySample(3)
        formulation.addMotionTask(self.com, gains["weight_linear_momentum"], 1, 0.0)

        angular = tsid.TaskAMEquality("angular_momentum", robot)
        angular.setKp(gains["angular_momentum_damping"] * np.ones(3))  # Ḣ_des = −Kp H
        angular.setKd(np.zeros(3))
        angular.setReference(tsid.TrajectorySample(3))
        mass = sum(inertia.mass for inertia in model.inertias)
        formulation.addMotionTask(angular, 1.0 / mass**2, 1, 0.0)

        actuation = tsid.TaskActuationBounds("torque_limits", robot)
        torque_limit = np.array(setup["torque_limit"])
        actuation.setBounds(-torque_limit, torque_limit)
        formulation.addActuationTask(actuation, 1.0, 0, 0.0)
        self.tasks += [posture, orientation, self.com, angular, actuation]

        self.solver = tsid.SolverHQuadProgFast("hqp")
        self.solver.resize(formulation.nVar, formulation.nEq, formulation.nIn)
        self.mass_matrix = pin.crba(model, model.createData(), q)
        self.position_com_in_world = pin.centerOfMass(model, model.createData(), q)

    def tick(
        self,
        q: np.ndarray,
        v: np.ndarray,
        com_desired: np.ndarray,
        com_velocity_desired: np.ndarray,
    ) -> tuple[Any, np.ndarray]:
        """One stateless tick: CoM reference, problem, solve, q̈, τ; the solution and forces."""
        self.com_reference.value(com_desired)
        self.com_reference.derivative(com_velocity_desired)
        self.com.setReference(self.com_reference)
        problem = self.formulation.computeProblemData(0.0, q, v)
        solution = self.solver.solve(problem)
        self.formulation.getAccelerations(solution)
        self.formulation.getActuatorForces(solution)
        return solution, self.formulation.getContactForces(solution)


def tsid_worker() -> None:
    """Serve TSID ticks over stdin/stdout, one JSON line per request and per reply.

    Requests: ``{"setup": {...}}`` first, then ``{"states": {...}}`` per chunk.
    Replies: the versions, problem size and model check; then per chunk the tick
    times (s), the number of failed solves and the total normal force per tick (N).
    """
    # The C++ libraries may print on stdout: the replies keep their own copy of it.
    replies = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)

    def reply(message: dict[str, Any]) -> None:
        replies.write(json.dumps(message) + "\n")
        replies.flush()

    from importlib.metadata import version

    problem = TsidStanding(json.loads(sys.stdin.readline())["setup"])
    reply(
        {
            "tsid": version("tsid"),
            "pinocchio": pin.__version__,
            "n_var": problem.formulation.nVar,
            "n_eq": problem.formulation.nEq,
            "n_in": problem.formulation.nIn,
            "mass_matrix": problem.mass_matrix.tolist(),
            "position_com_in_world": problem.position_com_in_world.tolist(),
        }
    )
    for line in sys.stdin:
        states = {key: np.array(value) for key, value in json.loads(line)["states"].items()}
        tick_s, normal_force_N, failures = [], [], 0
        for q, v, com, com_velocity in zip(
            states["q"],
            states["v"],
            states["com_desired"],
            states["com_velocity_desired"],
            strict=True,
        ):
            start = time.perf_counter()
            solution, forces = problem.tick(q, v, com, com_velocity)
            tick_s.append(time.perf_counter() - start)
            failures += solution.status != 0
            normal_force_N.append(float(forces[2::3].sum()))
        reply({"tick_s": tick_s, "failures": failures, "normal_force_N": normal_force_N})


# Poise's side, in the project's interpreter ----------------------------------------------


def find_tsid_python(given: str | None) -> tuple[str | None, str]:
    """The interpreter to run TSID in and where it came from, or None and why there is none.

    One named by ``--tsid-python`` or the environment must exist; whether it
    really has TSID shows when its worker starts.
    """
    import shutil

    for source, candidate in (
        ("--tsid-python", given),
        (f"${TSID_PYTHON_VARIABLE}", os.environ.get(TSID_PYTHON_VARIABLE)),
    ):
        if candidate:
            path = shutil.which(candidate)
            if path is None:
                sys.exit(f"{source} {candidate!r}: no such interpreter")
            return path, f"{source} {candidate}"
    if find_spec("tsid") is not None:
        return sys.executable, "this interpreter"
    return None, (
        "TSID skipped: no `tsid` in this interpreter, no --tsid-python, no "
        f"${TSID_PYTHON_VARIABLE}; to set one up see this script's docstring or "
        "docs/benchmarks.md (TSID side by side)"
    )


class TsidWorker:
    """TSID's worker process, started once in TSID's interpreter, fed one chunk at a time."""

    def __init__(self, python: str, setup: dict[str, Any]):
        self.process = subprocess.Popen(
            [python, os.path.abspath(__file__), WORKER_FLAG],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, **WORKER_ENVIRONMENT},
        )
        self.hello = self.request({"setup": setup})

    def request(self, message: dict[str, Any]) -> dict[str, Any]:
        """Send one request, wait for its reply; exit with the worker's error if it died."""
        assert self.process.stdin is not None and self.process.stdout is not None
        try:
            self.process.stdin.write(json.dumps(message) + "\n")
            self.process.stdin.flush()
        except BrokenPipeError:
            pass  # the worker died: its stderr says why, below
        line = self.process.stdout.readline()
        if not line:
            self.process.wait()
            assert self.process.stderr is not None
            detail = self.process.stderr.read().strip().splitlines()[-12:]
            sys.exit(
                f"the TSID worker ({self.process.args[0]}) stopped with exit code "
                f"{self.process.returncode} (is `tsid` installed there? see docs/benchmarks.md):"
                "\n  " + "\n  ".join(detail)
            )
        return json.loads(line)

    def close(self) -> None:
        """End of input: the worker returns."""
        assert self.process.stdin is not None
        self.process.stdin.close()
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()


def talos_urdf_path(tsid_python: str | None) -> str:
    """``talos_reduced.urdf`` of ``example-robot-data``, found by TSID's interpreter or this one."""
    find = (
        "import os; from example_robot_data.robots_loader import getModelPath; "
        f"print(os.path.join(getModelPath({TALOS_URDF!r}), {TALOS_URDF!r}))"
    )
    interpreters = [tsid_python] if tsid_python else []
    if find_spec("example_robot_data") is not None:
        interpreters.append(sys.executable)
    for interpreter in interpreters:
        found = subprocess.run([interpreter, "-c", find], capture_output=True, text=True)
        if found.returncode == 0:
            return found.stdout.strip().splitlines()[-1]
    sys.exit(
        "--model talos needs PyPI `example-robot-data` beside TSID "
        "(pip install --no-deps example-robot-data==4.3.0 in TSID's venv)"
    )


def load_robot(name: str, tsid_python: str | None) -> tuple[Any, Any, str, str]:
    """Poise's robot, a welcome whose standing pose is on the soles, the file and its format."""
    from pathlib import Path

    from controller_server.models import BUILTIN_MODELS, load_robot_model
    from controller_server.session import Session
    from protocol.messages import ContactSpec, Hello

    if name == "talos":
        path, model_format = talos_urdf_path(tsid_python), "urdf"
        contacts = [
            ContactSpec(name=contact, frame=frame, points_in_frame=TALOS_SOLE_CORNERS)
            for contact, frame in TALOS_SOLES.items()
        ]
        hello = Hello(model_text=Path(path).read_text(), model_format="urdf", contacts=contacts)
        robot = load_robot_model(
            model_text=hello.model_text, model_format="urdf", contacts=contacts
        )
    elif name in BUILTIN_MODELS:
        path, model_format = str(BUILTIN_MODELS[name]), "mjcf"
        hello, robot = Hello(model=name), load_robot_model(name)
    else:
        sys.exit(f"--model {name!r}: choose talos or one of {', '.join(BUILTIN_MODELS)}")
    multi_dof = [joint.name for joint in robot.joints if joint.nv != 1]
    if multi_dof:
        sys.exit(
            f"{name} has multi-DoF joints ({', '.join(multi_dof)}); TSID's posture task "
            "needs 1-DoF joints: use revolute_humanoid or talos"
        )
    # The URDF's root is at the origin; the server's standing pose has the soles on z = 0.
    welcome = Session(hello).welcome(0)
    return robot, welcome, path, model_format


def support_centre_references(robot: Any, inputs: list[Any]) -> tuple[np.ndarray, np.ndarray]:
    """Per state, Poise's CM target and damping reference (eq. 5.9): the soles' mean."""
    model, data = robot.model, robot.model.createData()
    frames = [contact.frame_id for contact in robot.contacts]
    positions_m, velocities_m_s = [], []
    for control_input in inputs:
        pin.forwardKinematics(model, data, control_input.q, control_input.v)
        pin.updateFramePlacements(model, data)
        positions_m.append(np.mean([data.oMf[f].translation for f in frames], axis=0))
        velocities_m_s.append(
            np.mean(
                [
                    pin.getFrameVelocity(model, data, f, pin.LOCAL_WORLD_ALIGNED).linear
                    for f in frames
                ],
                axis=0,
            )
        )
    return np.array(positions_m), np.array(velocities_m_s)


def check_same_robot(robot: Any, hello: dict[str, Any], q: np.ndarray, path: str) -> None:
    """Exit unless TSID's Pinocchio built the same robot (mass matrix and CM at ``q``)."""
    model = robot.model
    mass_matrix = pin.crba(model, model.createData(), q)
    # Only the upper triangle: Pinocchio 3's crba leaves the lower one empty.
    mass_matrix_gap = np.max(np.abs(np.triu(np.array(hello["mass_matrix"]) - mass_matrix)))
    com_gap_m = np.max(
        np.abs(
            np.array(hello["position_com_in_world"])
            - pin.centerOfMass(model, model.createData(), q)
        )
    )
    if mass_matrix_gap > 1e-8 * np.max(np.abs(mass_matrix)) or com_gap_m > 1e-9:
        sys.exit(
            f"TSID's Pinocchio built another robot from {path}: {mass_matrix_gap=:.3g}, "
            f"{com_gap_m=:.3g}"
        )


TSID_GOAL_RATIO = 0.5
TAIL_GOAL_RATIO = 2.0


def percentiles_s(samples: list[float]) -> tuple[float, float]:
    """p50 and p99 (s), the first ticks (cold caches) left out."""
    p50, p99 = np.percentile(samples[5:], [50, 99])
    return float(p50), float(p99)


def main() -> None:
    from clients.sampling import random_state
    from controller_server.controllers import create_controller
    from controller_server.controllers.base import ControllerFailed
    from controller_server.wire import control_input_from_state

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="revolute_humanoid", help="built-in name or talos")
    parser.add_argument("--ticks", type=int, default=600, help="seeded states")
    parser.add_argument("--chunks", type=int, default=3, help="alternations of the three")
    parser.add_argument("--tsid-python", help=f"interpreter with tsid (or ${TSID_PYTHON_VARIABLE})")
    args = parser.parse_args()
    tsid_python, tsid_source = find_tsid_python(args.tsid_python)
    robot, welcome, path, model_format = load_robot(args.model, tsid_python)
    model = robot.model

    rng = np.random.default_rng(0)
    both_feet = [True] * len(robot.contacts)
    inputs = [
        control_input_from_state(
            robot,
            random_state(welcome, rng).model_copy(update={"contact_flags": both_feet}),
            want_diagnostics=False,
        )[0]
        for _ in range(args.ticks)
    ]
    controllers = {
        f"poise {kernel}": create_controller(
            "momentum", robot, {"optimizer_period_ticks": 1, "kernel": kernel}
        )
        for kernel in ("compiled", "python")
    }
    controller = controllers["poise compiled"]
    from baselines import Floor  # here: TSID's interpreter runs this file without the project

    floor = Floor(model, rng)
    com_desired, com_velocity_desired = support_centre_references(robot, inputs)
    worker = None
    if tsid_python is not None:
        parameters = controller.parameters()
        setup = {
            "model_path": path,
            "model_format": model_format,
            "contact_frames": [contact.frame_name for contact in robot.contacts],
            "contact_points": [contact.points_in_frame.tolist() for contact in robot.contacts],
            "friction": [contact.friction_coefficient for contact in robot.contacts],
            "torque_limit": robot.torque_limit.tolist(),
            "reference_joint_position": np.asarray(parameters["reference_joint_position"]).tolist(),
            "gains": {key: float(parameters[key]) for key in POISE_GAINS},
            "check_q": inputs[0].q.tolist(),
        }
        worker = TsidWorker(tsid_python, setup)
        check_same_robot(robot, worker.hello, inputs[0].q, path)

    times_s: dict[str, list[float]] = {"floor": [], "tsid": []} | {k: [] for k in controllers}
    normal_force_N: dict[str, list[float]] = {"tsid": []} | {k: [] for k in controllers}
    failures = {"tsid": 0} | dict.fromkeys(controllers, 0)
    for chunk in range(args.chunks):
        part = slice(chunk * args.ticks // args.chunks, (chunk + 1) * args.ticks // args.chunks)
        for control_input in inputs[part]:
            start = time.perf_counter()
            floor.tick(control_input)
            times_s["floor"].append(time.perf_counter() - start)
        for key, poise in controllers.items():
            for control_input in inputs[part]:
                start = time.perf_counter()
                try:
                    output = poise.compute(control_input)
                except ControllerFailed:  # counted, not timed
                    failures[key] += 1
                    continue
                times_s[key].append(time.perf_counter() - start)
                normal_force_N[key].append(float(output.contact_force_in_world[:, 2].sum()))
        if worker is not None:
            result = worker.request(
                {
                    "states": {
                        "q": [control_input.q.tolist() for control_input in inputs[part]],
                        "v": [control_input.v.tolist() for control_input in inputs[part]],
                        "com_desired": com_desired[part].tolist(),
                        "com_velocity_desired": com_velocity_desired[part].tolist(),
                    }
                }
            )
            times_s["tsid"] += result["tick_s"]
            normal_force_N["tsid"] += result["normal_force_N"]
            failures["tsid"] += result["failures"]
    if worker is not None:
        worker.close()

    weight_N = robot.total_mass * float(np.linalg.norm(model.gravity.linear))
    print(
        f"model {args.model} (nv = {model.nv}, {robot.total_mass:.1f} kg, weight {weight_N:.0f} N)"
        f", {args.ticks} states near standing on both feet, {args.chunks} alternating chunks"
    )
    if worker is None:
        print(tsid_source)
    else:
        print(
            f"TSID {worker.hello['tsid']} (Pinocchio {worker.hello['pinocchio']}) from "
            f"{tsid_source}: {worker.hello['n_var']} variables, {worker.hello['n_eq']} "
            f"equalities, {worker.hello['n_in']} inequalities; Poise: Pinocchio {pin.__version__}"
        )
    labels = {
        "floor": "floor: computeAllTerms + centroidal map + DAQP",
        "tsid": "TSID: HQuadProgFast, 2 contacts, CoM, AM, posture",
        "poise compiled": "Poise momentum, compiled tick",
        "poise python": "Poise momentum, Python tick (specification)",
    }
    floor_p50_s = percentiles_s(times_s["floor"])[0]
    tsid_p50_s = percentiles_s(times_s["tsid"])[0] if times_s["tsid"] else None
    print(
        f"{'tick':<52}{'p50 µs':>8}{'p99 µs':>8}{'/ floor':>9}"
        + (f"{'/ TSID':>9}" if tsid_p50_s else "")
        + f"{'normal force N':>16}{'failed':>8}"
    )
    for key, label in labels.items():
        if not times_s[key]:
            continue
        p50_s, p99_s = percentiles_s(times_s[key])
        line = f"{label:<52}{p50_s * 1e6:>8.0f}{p99_s * 1e6:>8.0f}{p50_s / floor_p50_s:>8.1f}x"
        if tsid_p50_s is not None:
            line += f"{p50_s / tsid_p50_s:>8.1f}x"
        if key in normal_force_N:
            line += f"{np.percentile(normal_force_N[key], 50):>16.0f}{failures[key]:>8}"
        print(line)
    if tsid_p50_s is not None:
        p50_s, p99_s = percentiles_s(times_s["poise compiled"])
        ratio = p50_s / tsid_p50_s
        met = ratio <= TSID_GOAL_RATIO and p99_s <= TAIL_GOAL_RATIO * p50_s
        print(
            f"Poise momentum (compiled) / TSID, p50: {ratio:.2f}x; issue 35's goal p50 ≤ "
            f"{TSID_GOAL_RATIO}x TSID and p99 ≤ {TAIL_GOAL_RATIO:.0f}x p50: "
            + ("met" if met else "not met")
        )


if __name__ == "__main__":
    if sys.argv[1:] == [WORKER_FLAG]:
        tsid_worker()
    else:
        main()
