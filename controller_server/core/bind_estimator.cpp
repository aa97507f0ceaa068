// controller_server._core.ImuBaseEstimator: the compiled estimator of the IMU path for Python
// (estimation/compiled.py wraps it; estimation/imu_base.py is its specification).
//
// step() runs a whole tick with the GIL released and copies the estimate into fresh numpy
// arrays; an EstimatorInputError of the C++ becomes controller_server.errors'
// EstimatorInputError, with the same field and detail as the Python's.
#include <cstring>
#include <exception>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>

#include "bind_parts.hpp"
#include "estimator.hpp"

namespace nb = nanobind;
using namespace nb::literals;

namespace poise {

namespace {

using VectorRef = Eigen::Ref<const Eigen::VectorXd>;

// One session's estimator and the buffer its estimates are written to (allocated once).
struct EstimatorSession {
  ImuBaseEstimator estimator;
  BaseEstimateOut out;
};

// A fresh C-ordered float64 array holding a copy of `count` doubles.
nb::object copied_array(const double* data, std::initializer_list<npy_intp> shape) {
  npy_intp dims[2] = {0, 0};
  int ndim = 0;
  npy_intp count = 1;
  for (npy_intp extent : shape) {
    dims[ndim++] = extent;
    count *= extent;
  }
  PyObject* array = PyArray_SimpleNew(ndim, dims, NPY_DOUBLE);
  if (array == nullptr) throw nb::python_error();
  if (count > 0) {
    std::memcpy(PyArray_DATA(reinterpret_cast<PyArrayObject*>(array)), data,
                static_cast<std::size_t>(count) * sizeof(double));
  }
  return nb::steal(array);
}

// bool(flag) of each contact flag (Python's truth), and how many there are.
ContactFlags read_flags(nb::handle flags) {
  nb::object sequence = nb::steal(PySequence_Fast(flags.ptr(), "contact_flags must be a sequence"));
  if (!sequence.is_valid()) throw nb::python_error();
  const Py_ssize_t count = PySequence_Fast_GET_SIZE(sequence.ptr());
  PyObject** items = PySequence_Fast_ITEMS(sequence.ptr());
  ContactFlags out;
  out.count = static_cast<std::size_t>(count);
  for (Py_ssize_t k = 0; k < count && k < 32; ++k) {
    const int truth = PyObject_IsTrue(items[k]);
    if (truth < 0) throw nb::python_error();
    if (truth) out.mask |= std::uint32_t{1} << k;
  }
  return out;
}

EstimatorNoise noise_from(nb::handle noise) {
  const auto number = [&](const char* name) { return nb::cast<double>(noise.attr(name)); };
  EstimatorNoise out{number("gyro_noise_density"),     number("accel_noise_density"),
                     number("gyro_bias_random_walk"),  number("accel_bias_random_walk"),
                     number("joint_position_noise"),   number("contact_position_noise"),
                     number("contact_slip_random_walk"), std::nullopt};
  const nb::object ground = noise.attr("flat_ground");
  if (!ground.is_none()) out.flat_ground = nb::cast<double>(ground);
  return out;
}

EstimatorPrior prior_from(nb::handle prior) {
  const auto number = [&](const char* name) { return nb::cast<double>(prior.attr(name)); };
  return {number("roll_pitch_rad"), number("yaw_rad"),           number("velocity"),
          number("position"),       number("gyro_bias"),         number("gyro_bias_at_rest"),
          nb::cast<bool>(prior.attr("still_at_start")),           number("accel_bias")};
}

nb::tuple estimate_tuple(const BaseEstimateOut& out) {
  const auto contacts = static_cast<npy_intp>(out.stance.size());
  nb::list stance;
  for (int k : out.stance) stance.append(k);
  return nb::make_tuple(
      copied_array(out.position_base_in_world.data(), {3}),
      copied_array(out.orientation_base_in_world_xyzw.data(), {4}),
      copied_array(out.linear_velocity_base_in_world.data(), {3}),
      copied_array(out.angular_velocity_base_in_base.data(), {3}),
      copied_array(out.gyro_bias_in_imu.data(), {3}), copied_array(out.accel_bias_in_imu.data(), {3}),
      // (3, n) column-major is (n, 3) row-major: one point after the other.
      copied_array(out.position_contacts_in_world.data(), {contacts, 3}), nb::tuple(stance),
      copied_array(out.covariance.data(), {15, 15}));
}

nb::tuple step(EstimatorSession& session, double time_s, VectorRef joint_position,
               nb::handle contact_flags, VectorRef angular_velocity_imu_in_imu,
               VectorRef linear_acceleration_imu_in_imu, nb::handle orientation_imu_in_world_xyzw) {
  const ContactFlags flags = read_flags(contact_flags);
  // The orientation is read only when the filter starts (a copy then: not every tick).
  std::optional<Eigen::VectorXd> orientation;
  if (!orientation_imu_in_world_xyzw.is_none() && !session.estimator.filter().initialized()) {
    orientation = nb::cast<Eigen::VectorXd>(orientation_imu_in_world_xyzw);
  }
  std::optional<VectorRef> orientation_ref;
  if (orientation) orientation_ref.emplace(*orientation);
  {
    nb::gil_scoped_release release;
    std::lock_guard<std::mutex> lock(session.estimator.mutex());
    session.estimator.step(time_s, joint_position, flags, angular_velocity_imu_in_imu,
                           linear_acceleration_imu_in_imu, orientation_ref ? &*orientation_ref : nullptr,
                           session.out);
  }
  return estimate_tuple(session.out);
}

// The whole state, with imu_base's and base_estimator's names (columns as rows, as Python).
nb::dict state(EstimatorSession& session) {
  std::lock_guard<std::mutex> lock(session.estimator.mutex());
  const FilterState filter = session.estimator.filter().state();
  const auto columns = static_cast<npy_intp>(filter.columns.cols());
  const auto dim = static_cast<npy_intp>(filter.covariance.rows());
  const Eigen::Matrix<double, 3, 3, Eigen::RowMajor> rotation = filter.rotation;
  const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> covariance =
      filter.covariance;
  nb::dict out;
  out["rotation"] = copied_array(rotation.data(), {3, 3});
  out["columns"] = copied_array(filter.columns.data(), {columns, 3});
  out["bias"] = copied_array(filter.bias.data(), {6});
  out["covariance"] = copied_array(covariance.data(), {dim, dim});
  nb::list stance;
  for (int k : filter.stance) stance.append(k);
  out["stance"] = stance;
  out["gyro_reading"] = copied_array(filter.gyro_reading.data(), {3});
  out["initialized"] = filter.initialized;
  out["time_s"] = session.estimator.time_s();
  nb::list corners;
  for (CornerSet used : session.estimator.corners()) {
    nb::list indices;
    for (int i = 0; i < 32; ++i) {
      if (used >> i & 1U) indices.append(i);
    }
    corners.append(nb::tuple(indices));
  }
  out["corners"] = corners;
  return out;
}

void set_state(EstimatorSession& session, nb::dict values) {
  FilterState filter;
  filter.rotation = nb::cast<Eigen::Matrix3d>(values["rotation"]);
  const Eigen::MatrixXd columns = nb::cast<Eigen::MatrixXd>(values["columns"]);
  const Eigen::MatrixXd covariance = nb::cast<Eigen::MatrixXd>(values["covariance"]);
  if (columns.cols() != 3 || columns.rows() < 2 || columns.rows() > 2 + kMaxContacts ||
      covariance.rows() > kMaxStateDim || covariance.cols() > kMaxStateDim) {
    throw std::invalid_argument("columns must be (2 + K, 3) and the covariance at most " +
                                std::to_string(kMaxStateDim) + " square");
  }
  filter.columns = columns.transpose();
  filter.bias = nb::cast<Eigen::VectorXd>(values["bias"]);
  filter.covariance = covariance;
  filter.stance = nb::cast<std::vector<int>>(values["stance"]);
  filter.gyro_reading = nb::cast<Eigen::Vector3d>(values["gyro_reading"]);
  filter.initialized = nb::cast<bool>(values["initialized"]);
  std::vector<CornerSet> corners;
  for (nb::handle used : nb::cast<nb::list>(values["corners"])) {
    CornerSet set = 0;
    for (nb::handle index : used) set |= CornerSet{1} << nb::cast<int>(index);
    corners.push_back(set);
  }
  std::lock_guard<std::mutex> lock(session.estimator.mutex());
  session.estimator.filter().set_state(filter);
  session.estimator.set_session_state(nb::cast<double>(values["time_s"]), corners);
}

}  // namespace

void bind_estimator(nb::module_& m) {
  if (_import_array() < 0) throw nb::python_error();  // NumPy's C API, in this unit too

  nb::register_exception_translator([](const std::exception_ptr& pointer, void*) {
    try {
      std::rethrow_exception(pointer);
    } catch (const EstimatorInputError& error) {
      const nb::object type =
          nb::module_::import_("controller_server.errors").attr("EstimatorInputError");
      const nb::object instance = type(error.field(), error.detail());
      PyErr_SetObject(type.ptr(), instance.ptr());
    }
  });

  nb::class_<EstimatorSession>(
      m, "ImuBaseEstimator",
      "One session's contact-aided invariant EKF of the IMU path (estimation/imu_base.py).")
      .def(
          "__init__",
          [](EstimatorSession* self, const std::string& model_text,
             const std::vector<std::size_t>& frame_ids, const std::vector<Points>& corners_per_contact,
             const Eigen::Matrix3d& rotation_imu_to_base, const Eigen::Vector3d& position_imu_in_base,
             nb::handle noise, nb::handle level_prior, nb::handle ahrs_prior, double gravity,
             double max_state_gap_s, double grounded_tolerance_m) {
            std::vector<pinocchio::FrameIndex> frames(frame_ids.begin(), frame_ids.end());
            const EstimatorNoise noise_values = noise_from(noise);
            const EstimatorPrior level = prior_from(level_prior), ahrs = prior_from(ahrs_prior);
            std::shared_ptr<const Model> model;
            {
              nb::gil_scoped_release release;  // parsing the model's text: let others run
              model = model_from_string(model_text);
            }
            new (self) EstimatorSession{
                ImuBaseEstimator(std::move(model), std::move(frames), corners_per_contact,
                                 ImuMount{rotation_imu_to_base, position_imu_in_base}, noise_values,
                                 level, ahrs, gravity, max_state_gap_s, grounded_tolerance_m),
                BaseEstimateOut{}};
            self->out.stance.reserve(kMaxContacts);
          },
          "model_text"_a, "frame_ids"_a, "corners_per_contact"_a, "rotation_imu_to_base"_a,
          "position_imu_in_base"_a, "noise"_a, "level_prior"_a, "ahrs_prior"_a, "gravity"_a,
          "max_state_gap_s"_a, "grounded_tolerance_m"_a,
          "From `pin.Model.saveToString()`, each contact's frame id and (k, 3) sole corners, the "
          "IMU mount, an EstimatorNoise, the priors levelled on the accelerometer and from an "
          "AHRS (EstimatorPrior), gravity (m/s²), the longest gap between states (s) and the "
          "grounded tolerance (m).")
      .def("step", &step, "time_s"_a, "joint_position"_a, "contact_flags"_a,
           "angular_velocity_imu_in_imu"_a, "linear_acceleration_imu_in_imu"_a,
           "orientation_imu_in_world_xyzw"_a.none(),
           "One tick (GIL released): (position, quaternion xyzw, velocity, angular velocity, gyro "
           "bias, accel bias, stance points (n, 3), stance contact indices, covariance (15, 15)), "
           "fresh arrays. Raises EstimatorInputError as ImuBaseEstimator's filter does (the "
           "estimator's field names).")
      .def("state", &state, "The filter's and the session's state (a dict of copies).")
      .def("set_state", &set_state, "values"_a, "Take over a state() (or the Python's).")
      .def_prop_ro("nq", [](EstimatorSession& s) { return s.estimator.model().nq; })
      .def_prop_ro("contact_count", [](EstimatorSession& s) { return s.estimator.contact_count(); });
}

}  // namespace poise
