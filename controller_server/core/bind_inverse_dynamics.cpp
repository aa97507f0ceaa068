// _core.InverseDynamics: poise::InverseDynamics for the agreement tests and the bench.
//
// solve() takes a Python DynamicsTerms (copied into a poise::Terms with the GIL held),
// releases the GIL for the C++ work, and returns a dict of fresh arrays with the field
// names of InverseDynamicsResult (inverse_dynamics.py) and `path`. time_solve() repeats
// the C++ solve alone and returns its durations, for bench/inverse_dynamics_core.py.
#include <chrono>
#include <mutex>
#include <cstdint>
#include <optional>
#include <utility>
#include <vector>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/stl/vector.h>

#include "bind_parts.hpp"
#include "bind_terms.hpp"
#include "inverse_dynamics.hpp"

namespace nb = nanobind;
using namespace nb::literals;

namespace {

using poise::InverseDynamics;
using poise::InverseDynamicsResult;
using poise::InverseDynamicsStatus;

// One call's inputs, converted with the GIL held.
struct Request {
  poise::Terms terms;
  Eigen::VectorXd acceleration;
  std::vector<bool> supports;
  Eigen::VectorXd friction_coefficients;
  std::optional<poise::RowMatrix> measured_wrenches;
  poise::InverseDynamicsWeights weights;
};

Request make_request(nb::handle terms, nb::handle acceleration, nb::handle supports,
                     nb::handle friction_coefficients, nb::handle measured_wrenches,
                     double force_regularization, double support_weight) {
  nb::module_ np = nb::module_::import_("numpy");
  const auto vector = [&np](nb::handle value) {
    return nb::cast<Eigen::VectorXd>(np.attr("asarray")(value, "dtype"_a = "float64"));
  };
  Request request{poise::terms_from_python(terms), vector(acceleration), {},
                  vector(friction_coefficients), std::nullopt,
                  {force_regularization, support_weight}};
  for (nb::handle flag : supports) {
    const int truth = PyObject_IsTrue(flag.ptr());  // any truthy flag, as `if on` in Python
    if (truth < 0) throw nb::python_error();
    request.supports.push_back(truth == 1);
  }
  if (!measured_wrenches.is_none()) {
    // As the Python: np.asarray(measured_wrenches, dtype=float).reshape(-1, 6).
    nb::object wrenches =
        np.attr("asarray")(measured_wrenches, "dtype"_a = "float64").attr("reshape")(-1, 6);
    request.measured_wrenches = nb::cast<poise::RowMatrix>(wrenches);
  }
  return request;
}

const InverseDynamicsResult& run(InverseDynamics& solver, const Request& request) {
  if (request.measured_wrenches) {
    return solver.solve_measured(request.terms, request.acceleration, *request.measured_wrenches);
  }
  return solver.solve(request.terms, request.acceleration, request.supports,
                      request.friction_coefficients, request.weights);
}

// A status other than ok as the Python error: ValueError for non-finite inputs (the
// Python would return NaNs or no answer), np.linalg.LinAlgError as _realize raises it.
void raise_status(const InverseDynamicsResult& result) {
  switch (result.status) {
    case InverseDynamicsStatus::ok:
      return;
    case InverseDynamicsStatus::non_finite_input:
      throw nb::value_error(result.detail);
    case InverseDynamicsStatus::mass_matrix_not_positive: {
      nb::object error = nb::module_::import_("numpy").attr("linalg").attr("LinAlgError");
      PyErr_SetString(error.ptr(), result.detail);
      throw nb::python_error();
    }
  }
}

nb::dict solve(InverseDynamics& solver, nb::handle terms, nb::handle acceleration,
               nb::handle supports, nb::handle friction_coefficients,
               nb::handle measured_wrenches, double force_regularization,
               double support_weight) {
  const Request request = make_request(terms, acceleration, supports, friction_coefficients,
                                       measured_wrenches, force_regularization, support_weight);
  InverseDynamicsResult result;  // a copy of the solver's, taken under its lock
  {
    nb::gil_scoped_release release;
    const std::lock_guard<std::mutex> lock(solver.mutex());
    result = run(solver, request);
  }
  raise_status(result);
  // Fresh arrays: nanobind's Eigen caster moves each (copied) matrix into a new numpy array.
  nb::dict out;
  out["joint_torque"] = nb::cast(std::move(result.joint_torque));
  out["contact_force_in_world"] = nb::cast(std::move(result.contact_force_in_world));
  out["contact_wrench_in_world"] = nb::cast(std::move(result.contact_wrench_in_world));
  out["acceleration"] = nb::cast(std::move(result.acceleration));
  out["root_wrench_residual"] = nb::float_(result.root_wrench_residual);
  out["saturated_joints"] = nb::int_(result.saturated_joints);
  out["path"] = nb::str(poise::path_name(result.path));
  out["qp_iterations"] = nb::int_(result.qp_iterations);
  out["qp_failures"] = nb::int_(result.qp_failures);
  return out;
}

// The C++ solve alone, `repeats` times on the same inputs: each call's duration (s).
Eigen::VectorXd time_solve(InverseDynamics& solver, nb::handle terms, nb::handle acceleration,
                           nb::handle supports, nb::handle friction_coefficients,
                           nb::handle measured_wrenches, double force_regularization,
                           double support_weight, std::int64_t repeats) {
  if (repeats < 1) throw nb::value_error("repeats must be >= 1");
  const Request request = make_request(terms, acceleration, supports, friction_coefficients,
                                       measured_wrenches, force_regularization, support_weight);
  Eigen::VectorXd durations_s(repeats);
  InverseDynamicsStatus status = InverseDynamicsStatus::ok;
  const char* detail = "";
  {
    nb::gil_scoped_release release;
    const std::lock_guard<std::mutex> lock(solver.mutex());
    using Clock = std::chrono::steady_clock;
    for (std::int64_t i = 0; i < repeats; ++i) {
      const Clock::time_point start = Clock::now();
      const InverseDynamicsResult& result = run(solver, request);
      durations_s[i] = std::chrono::duration<double>(Clock::now() - start).count();
      status = result.status;
      detail = result.detail;
    }
  }
  InverseDynamicsResult outcome;
  outcome.status = status;
  outcome.detail = detail;
  raise_status(outcome);
  return durations_s;
}

}  // namespace

namespace poise {

void bind_inverse_dynamics(nb::module_& m) {
  nb::class_<InverseDynamics>(
      m, "InverseDynamics",
      "inverse_dynamics.solve_inverse_dynamics in C++: one session's sizes, torque limits and "
      "workspaces (eiquadprog, Goldfarb–Idnani, for the QP cases: the Python path's quadprog "
      "method).")
      .def(nb::init<Eigen::Index, std::vector<Eigen::Index>, Eigen::VectorXd>(), "nv"_a,
           "point_counts"_a, "torque_limit"_a,
           "nv DoFs (a free-flyer root first), each contact's number of sole points, and the "
           "(nv - 6,) symmetric torque limits.")
      .def("solve", &solve, "terms"_a, "acceleration"_a, "supports"_a,
           "friction_coefficients"_a, "measured_wrenches"_a = nb::none(),
           "force_regularization"_a = 1e-4, "support_weight"_a = 100.0,
           "solve_inverse_dynamics(terms, ...) with qp_solver='quadprog': a dict of new arrays "
           "(InverseDynamicsResult's field names), `path` (measured, exact, condensed_qp, "
           "full_qp or least_squares), `qp_iterations` (active-set iterations, summed) and "
           "`qp_failures` (its solves without an answer). ValueError on non-finite inputs.")
      .def("time_solve", &time_solve, "terms"_a, "acceleration"_a, "supports"_a,
           "friction_coefficients"_a, "measured_wrenches"_a = nb::none(),
           "force_regularization"_a = 1e-4, "support_weight"_a = 100.0, "repeats"_a = 1000,
           "The C++ solve alone, repeated on the same inputs: each call's duration (s).")
      .def_prop_ro("nv", &InverseDynamics::nv)
      .def_prop_ro("support_set_count", &InverseDynamics::support_set_count,
                   "Support-flag combinations seen (each holds its own workspace).")
      .def_prop_ro("qp_cache_size", &InverseDynamics::qp_cache_size,
                   "QP solvers held (at most two per support combination).")
      .def_prop_ro("workspace_allocations", &InverseDynamics::workspace_allocations,
                   "Heap allocations of workspaces since construction (support sets, QPs).");
}

}  // namespace poise
