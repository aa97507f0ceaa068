// _core.WeightedTick: the weighted controllers' tick (weighted_tick.hpp) for Python.
#include <string>
#include <vector>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include "bind_parts.hpp"
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

// The optimizer alone at (q, v): the agreement tests' entry (q̈ of eq. 5.1).
Eigen::VectorXd optimize(WeightedTick& tick, VectorRef q, VectorRef v,
                         const std::vector<bool>& supports,
                         std::optional<Eigen::Ref<const RowMatrix>> wrenches, VectorRef limit_errors,
                         VectorRef q_ref, VectorRef v_ref, VectorRef a_ref) {
  const RowMatrix none(0, 6);
  {
    nb::gil_scoped_release release;
    tick.prepare(q, v);
    tick.optimize(q, v, supports, wrenches ? *wrenches : Eigen::Ref<const RowMatrix>(none),
                  limit_errors, q_ref, v_ref, a_ref);
  }
  return tick.acceleration_desired();
}

}  // namespace

void bind_weighted(nb::module_& m) {
  nb::class_<WeightedTick>(m, "WeightedTick",
                           "The weighted controllers' tick (Macchietto 2008, eq. 5.1 and 4.2).")
      .def(
          "__init__",
          [](WeightedTick* self, const DynamicsCore& core) { new (self) WeightedTick(core); },
          "core"_a, "A workspace on `core`'s model and contacts.")
      .def("set_params", &set_params, "values"_a,
           "Take the optimizer's parameters from a dict of parameter values (those present).")
      .def("set_points", &set_points, "targets"_a,
           "Point targets as (name, frame_id, offset, position, velocity, k_s, k_d, weight).")
      .def("reset", &WeightedTick::reset, "Forget the last solution.")
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
      .def("optimize", &optimize, "q"_a, "v"_a, "supports"_a, "wrenches"_a.none(),
           "limit_errors"_a, "q_ref"_a, "v_ref"_a, "a_ref"_a,
           "The dynamics terms and the optimizer at (q, v): q̈ of eq. 5.1.");
}

}  // namespace poise
