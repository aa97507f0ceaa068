// _core.WeightedTick: the weighted controllers' tick (weighted_tick.hpp) for Python.
#include <chrono>
#include <string>
#include <vector>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include "bind_parts.hpp"
#include "joint_limits.hpp"
#include "weighted_tick.hpp"

namespace nb = nanobind;
using namespace nb::literals;

namespace poise {

namespace {

using VectorRef = Eigen::Ref<const Eigen::VectorXd>;

// A parameter's vector value: a numpy array or a list of numbers (defaults are lists).
Eigen::VectorXd to_vector(nb::handle value) {
  if (nb::isinstance<nb::list>(value) || nb::isinstance<nb::tuple>(value)) {
    const std::vector<double> numbers = nb::cast<std::vector<double>>(value);
    return Eigen::Map<const Eigen::VectorXd>(numbers.data(), static_cast<Eigen::Index>(numbers.size()));
  }
  return nb::cast<Eigen::VectorXd>(value);
}

// The optimizer's parameters from MomentumController.in_force() (a dict of wire values).
void set_params(WeightedTick& tick, const nb::dict& values) {
  WeightedParams& p = tick.params;
  const auto number = [&values](const char* key, double& into) {
    if (values.contains(key)) into = nb::cast<double>(values[key]);
  };
  const auto vector = [&values](const char* key, Eigen::VectorXd& into) {
    if (values.contains(key)) into = to_vector(values[key]);
  };
  number("stiffness", p.stiffness);
  number("damping", p.damping);
  number("weight_tracking", p.weight_tracking);
  number("weight_root_orientation", p.weight_root_orientation);
  vector("joint_weights", p.joint_weights);
  number("joint_limit_stiffness", p.joint_limit_stiffness);
  number("joint_limit_damping", p.joint_limit_damping);
  number("weight_linear_momentum", p.weight_linear_momentum);
  number("momentum_stiffness", p.momentum_stiffness);
  number("momentum_damping", p.momentum_damping);
  if (values.contains("com_offset_xy")) {
    p.com_offset_xy = to_vector(values["com_offset_xy"]).head<2>();
  }
  number("cop_margin", p.cop_margin);
  number("angular_momentum_gain", p.angular_momentum_gain);
  number("angular_momentum_damping", p.angular_momentum_damping);
  number("weight_angular_momentum", p.weight_angular_momentum);
  number("ground_height", p.ground_height);
  vector("friction_coefficients", p.friction_coefficients);
  number("objective_gain_bound", p.objective_gain_bound);
  number("constraint_gain_bound", p.constraint_gain_bound);
  if (values.contains("ground_force_mode")) {
    tick.measured_ground_forces = nb::cast<std::string>(values["ground_force_mode"]) == "measured";
  }
  number("force_regularization", tick.weights.force_regularization);
  number("support_weight", tick.weights.support_weight);
  if (values.contains("optimizer_period_ticks")) {
    tick.optimizer_period_ticks = nb::cast<int>(values["optimizer_period_ticks"]);
  }
  const Model& model = tick.model();
  if (values.contains("reference_joint_position") ||
      values.contains("reference_base_orientation_xyzw")) {
    p.reference_configuration = Eigen::VectorXd::Zero(model.nq);
    p.reference_configuration(6) = 1.0;
    if (values.contains("reference_base_orientation_xyzw")) {
      p.reference_configuration.segment<4>(3) =
          to_vector(values["reference_base_orientation_xyzw"]);
    }
    if (values.contains("reference_joint_position")) {
      p.reference_configuration.tail(model.nq - 7) =
          to_vector(values["reference_joint_position"]);
    }
  }
}

// Point targets: (name, frame_id, offset, position, velocity, stiffness, damping, weight).
void set_points(WeightedTick& tick, const nb::list& targets) {
  tick.points.clear();
  for (nb::handle item : targets) {
    const nb::tuple t = nb::cast<nb::tuple>(item);
    PointTarget target;
    target.name = nb::cast<std::string>(t[0]);
    target.frame_id = nb::cast<std::size_t>(t[1]);
    if (target.frame_id >= static_cast<std::size_t>(tick.model().nframes)) {
      throw std::invalid_argument("point target frame id out of range");
    }
    target.offset_in_frame = to_vector(t[2]);
    target.target_position_in_world = to_vector(t[3]);
    target.target_velocity_in_world = to_vector(t[4]);
    target.stiffness = nb::cast<double>(t[5]);
    target.damping = nb::cast<double>(t[6]);
    target.weight = nb::cast<double>(t[7]);
    tick.points.push_back(target);
  }
}

// A new float64 array (copy) of an Eigen expression, as numpy wants it (C order).
template <typename Derived>
nb::object array(const Eigen::MatrixBase<Derived>& value) {
  using Plain = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  return nb::cast(Plain(value));
}
nb::object vector(const Eigen::Ref<const Eigen::VectorXd>& value) {
  return nb::cast(Eigen::VectorXd(value));
}

// The state's sizes against the tick's model and contacts (ValueError otherwise).
void check_state(const WeightedTick& tick, VectorRef q, VectorRef v,
                 const std::vector<bool>& supports) {
  const Model& model = tick.model();
  if (q.size() != model.nq || v.size() != model.nv) {
    throw std::invalid_argument("q or v has the wrong size");
  }
  if (supports.size() != tick.terms().contacts.size()) {
    throw std::invalid_argument("one support flag per contact is needed");
  }
}

// One whole tick: a dict of fresh arrays (ControlOutput's fields), "failure" (str or None),
// "optimizer_ran", and with want_diagnostics what MomentumController._diagnostics reads.
nb::dict compute(WeightedTick& tick, VectorRef q, VectorRef v, const std::vector<bool>& supports,
                 std::optional<Eigen::Ref<const RowMatrix>> measured_wrenches,
                 std::optional<VectorRef> q_ref,
                 std::optional<VectorRef> v_ref, std::optional<VectorRef> a_ref, bool prepared,
                 bool want_diagnostics) {
  check_state(tick, q, v, supports);
  const RowMatrix none(0, 6);
  const Eigen::VectorXd empty(0);
  std::string failure;
  {
    nb::gil_scoped_release release;
    failure = tick.compute(q, v, supports, measured_wrenches ? *measured_wrenches : Eigen::Ref<const RowMatrix>(none),
                           q_ref ? *q_ref : VectorRef(empty),
                           v_ref ? *v_ref : VectorRef(empty), a_ref ? *a_ref : VectorRef(empty),
                           prepared, want_diagnostics);
  }
  nb::dict out;
  out["failure"] = failure.empty() ? nb::none() : nb::cast(failure);
  out["optimizer_ran"] = tick.optimizer_ran();
  if (!failure.empty()) return out;
  const InverseDynamicsResult& result = tick.result();
  out["acceleration"] = vector(result.acceleration);
  out["joint_torque"] = vector(result.joint_torque);
  out["contact_force_in_world"] = array(result.contact_force_in_world);
  out["contact_wrench_in_world"] = array(result.contact_wrench_in_world);
  out["root_wrench_residual"] = result.root_wrench_residual;
  out["saturated_joints"] = result.saturated_joints;
  out["inverse_dynamics_path"] = path_name(result.path);
  if (!want_diagnostics) return out;
  const TickDiagnostics& d = tick.diagnostics();
  const OptimizerReport& report = tick.optimizer().report();
  out["position_com_in_world"] = vector(d.position_com_in_world);
  out["linear_momentum"] = vector(d.linear_momentum);
  out["angular_momentum"] = vector(d.angular_momentum);
  out["linear_momentum_rate"] = vector(d.linear_momentum_rate);
  out["angular_momentum_rate"] = vector(d.angular_momentum_rate);
  Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor> polygon(
      static_cast<Eigen::Index>(d.support_polygon.size()), 2);
  for (std::size_t i = 0; i < d.support_polygon.size(); ++i) {
    polygon.row(static_cast<Eigen::Index>(i)) = d.support_polygon[i].transpose();
  }
  out["support_polygon_xy"] = nb::cast(polygon);
  out["position_contact_frames_in_world"] = array(tick.terms().position_contact_frames_in_world);
  nb::dict residuals;
  for (const auto& [name, value] : d.objective_residuals) residuals[name.c_str()] = value;
  out["objective_residuals"] = residuals;
  out["linear_momentum_rate_desired"] = vector(report.linear_momentum_rate_desired);
  out["angular_momentum_rate_desired"] = vector(report.angular_momentum_rate_desired);
  out["angular_momentum_weight"] = report.angular_momentum_weight;
  out["constraint_residual"] = report.kkt.constraint_residual;
  out["objective_condition_number"] = report.kkt.objective_condition_number;
  out["schur_condition_number"] = report.kkt.schur_condition_number;
  out["objective_damping"] = report.kkt.objective_damping;
  out["constraint_damping"] = report.kkt.constraint_damping;
  return out;
}

// `repeats` whole ticks at one state in C++ (no Python between them, no outputs copied):
// per-tick seconds, for the benchmarks and the allocation count of the tests.
std::vector<double> time_compute(WeightedTick& tick, VectorRef q, VectorRef v,
                                 const std::vector<bool>& supports, int repeats) {
  check_state(tick, q, v, supports);
  if (repeats < 0) throw std::invalid_argument("repeats < 0");
  std::vector<double> seconds(static_cast<std::size_t>(repeats));
  const RowMatrix none(0, 6);
  const Eigen::VectorXd empty(0);
  {
    nb::gil_scoped_release release;
    for (double& duration : seconds) {
      const auto start = std::chrono::steady_clock::now();
      const std::string failure =
          tick.compute(q, v, supports, none, empty, empty, empty, false, false);
      duration = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      if (!failure.empty()) break;
    }
  }
  return seconds;
}

// What a behaviour observes of the prepared state (behaviors.Observation's fields).
nb::dict observation(const WeightedTick& tick) {
  const Terms& terms = tick.terms();
  nb::dict out;
  out["position_com_in_world"] = vector(terms.position_com_in_world);
  out["velocity_com_in_world"] = vector(terms.linear_momentum / terms.total_mass);
  out["position_contact_frames_in_world"] = array(terms.position_contact_frames_in_world);
  const std::vector<ContactSpec>& contacts = tick.core().contacts();
  RowMatrix rotations(static_cast<Eigen::Index>(3 * contacts.size()), 3);
  for (std::size_t c = 0; c < contacts.size(); ++c) {
    rotations.middleRows<3>(static_cast<Eigen::Index>(3 * c)) =
        tick.data().oMf[contacts[c].frame_id].rotation();
  }
  out["orientation_contact_frames_in_world"] = nb::cast(rotations);  // (3 contacts, 3)
  return out;
}

}  // namespace

void bind_weighted(nb::module_& m) {
  nb::class_<WeightedTick>(m, "WeightedTick",
                           "The weighted controllers' tick (Macchietto 2008, eq. 5.1 and 4.2).")
      .def(
          "__init__",
          [](WeightedTick* self, const DynamicsCore& core, const Eigen::VectorXd& torque_limit) {
            new (self) WeightedTick(core, torque_limit);
          },
          "core"_a, "torque_limit"_a,
          "A workspace on `core`'s model and contacts, with the joints' torque limits.")
      .def("set_params", &set_params, "values"_a,
           "Take the optimizer's parameters from a dict of parameter values (those present).")
      .def("set_points", &set_points, "targets"_a,
           "Point targets as (name, frame_id, offset, position, velocity, k_s, k_d, weight).")
      .def_prop_ro(
          "report",
          [](WeightedTick& tick) {
            const OptimizerReport& r = tick.optimizer().report();
            nb::dict d;
            d["linear_momentum_rate_desired"] = Eigen::VectorXd(r.linear_momentum_rate_desired);
            d["angular_momentum_rate_desired"] = Eigen::VectorXd(r.angular_momentum_rate_desired);
            d["angular_momentum_weight"] = r.angular_momentum_weight;
            d["found"] = r.kkt.found;
            d["objective_damping"] = r.kkt.objective_damping;
            d["constraint_damping"] = r.kkt.constraint_damping;
            d["constraint_residual"] = r.kkt.constraint_residual;
            d["objective_condition_number"] = r.kkt.objective_condition_number;
            d["schur_condition_number"] = r.kkt.schur_condition_number;
            return d;
          },
          "What the last optimizer run reports (desired momentum rates, β_ba, the KKT's).")
      .def("set_limits", &WeightedTick::set_limits, "limits"_a,
           "The soft joint limits (a JointLimits) whose errors raise the tracking gains.")
      .def_prop_ro(
          "acceleration_desired",
          [](const WeightedTick& tick) { return Eigen::VectorXd(tick.acceleration_desired()); },
          "The last optimizer run's q̈ (before the inverse dynamics makes it feasible).")
      .def_prop_ro(
          "inverse_dynamics_path",
          [](const WeightedTick& tick) { return std::string(path_name(tick.result().path)); },
          "Which branch of the inverse dynamics answered the last tick.")
      .def("optimizer_due", &WeightedTick::optimizer_due, "supports"_a,
           "Whether the next tick with these supports runs the optimizer.")
      .def("prepare", &WeightedTick::prepare, "q"_a, "v"_a,
           nb::call_guard<nb::gil_scoped_release>(),
           "The dynamics terms at (q, v), for a behaviour to observe before compute(prepared=True).")
      .def("time_compute", &time_compute, "q"_a, "v"_a, "supports"_a, "repeats"_a,
           "Per-tick seconds of `repeats` ticks at one state, in C++ alone (the benchmarks).")
      .def("observation", &observation, "What a behaviour reads of the prepared state.")
      .def("compute", &compute, "q"_a, "v"_a, "supports"_a, "measured_wrenches"_a.none(),
           "q_ref"_a.none(), "v_ref"_a.none(), "a_ref"_a.none(),
           "prepared"_a = false, "want_diagnostics"_a = true,
           "One whole tick (terms, optimizer when due, inverse dynamics): a dict.");
}

}  // namespace poise
