// _core.BoxLimit, _core.BallLimit, _core.JointLimits: the soft joint-limit errors
// (joint_limits.hpp) for Python. JointLimitSet.compiled() (features/joint_limits.py) builds
// them from the Python limits; tests/controller_server/test_compiled_joint_limits.py holds
// errors(q) to JointLimitSet.errors(q).
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include "bind_parts.hpp"
#include "joint_limits.hpp"

namespace nb = nanobind;
using namespace nb::literals;

namespace poise {

namespace {

using ErrorsArray = nb::ndarray<nb::numpy, double, nb::ndim<1>, nb::c_contig>;

// JointLimits.errors for Python: a new (nv,) array. The GIL stays held: the call takes
// about a microsecond, less than releasing and taking it back would cost.
ErrorsArray errors(const JointLimits& limits, const Eigen::Ref<const Eigen::VectorXd>& q) {
  const auto nv = static_cast<std::size_t>(limits.nv());
  auto* data = new double[nv == 0 ? 1 : nv];
  nb::capsule owner(data, [](void* p) noexcept { delete[] static_cast<double*>(p); });
  limits.errors(q, Eigen::Map<Eigen::VectorXd>(data, limits.nv()));
  return ErrorsArray(data, {nv}, owner);
}

}  // namespace

void bind_joint_limits(nb::module_& m) {
  nb::class_<BoxLimit>(
      m, "BoxLimit",
      "A 1-DoF joint's box [lower, upper] (features.joint_limits.RevoluteJointLimit).")
      .def(
          "__init__",
          [](BoxLimit* self, std::string name, Eigen::Index idx_q, Eigen::Index idx_v,
             double lower, double upper) {
            new (self) BoxLimit{std::move(name), idx_q, idx_v, lower, upper};
          },
          "name"_a, "idx_q"_a, "idx_v"_a, "lower"_a, "upper"_a)
      .def_ro("name", &BoxLimit::name)
      .def_ro("idx_q", &BoxLimit::idx_q)
      .def_ro("idx_v", &BoxLimit::idx_v)
      .def_ro("lower", &BoxLimit::lower)
      .def_ro("upper", &BoxLimit::upper);

  nb::class_<BallLimit>(m, "BallLimit",
                        "A ball joint's swing cone and twist interval "
                        "(features.joint_limits.BallJointLimit and its SwingCone).")
      .def(
          "__init__",
          [](BallLimit* self, std::string name, Eigen::Index idx_q, Eigen::Index idx_v,
             const Eigen::Vector3d& bone_axis_in_parent, const UnitVectors& face_normals_in_parent,
             const UnitVectors& edges_in_parent, bool reflex, double twist_lower_rad,
             double twist_upper_rad) {
            new (self) BallLimit{std::move(name),         idx_q,           idx_v,
                                 bone_axis_in_parent,     face_normals_in_parent,
                                 edges_in_parent,         reflex,          twist_lower_rad,
                                 twist_upper_rad};
          },
          "name"_a, "idx_q"_a, "idx_v"_a, "bone_axis_in_parent"_a, "face_normals_in_parent"_a,
          "edges_in_parent"_a, "reflex"_a, "twist_lower_rad"_a, "twist_upper_rad"_a,
          "SwingCone's face_normals_in_parent and edges_in_parent as (k, 3) arrays.")
      .def_ro("name", &BallLimit::name)
      .def_ro("idx_q", &BallLimit::idx_q)
      .def_ro("idx_v", &BallLimit::idx_v)
      .def_ro("bone_axis_in_parent", &BallLimit::bone_axis_in_parent)
      .def_ro("face_normals_in_parent", &BallLimit::face_normals_in_parent)
      .def_ro("edges_in_parent", &BallLimit::edges_in_parent)
      .def_ro("reflex", &BallLimit::reflex)
      .def_ro("twist_lower_rad", &BallLimit::twist_lower_rad)
      .def_ro("twist_upper_rad", &BallLimit::twist_upper_rad);

  nb::class_<JointLimits>(m, "JointLimits",
                          "A robot's soft joint limits (features.joint_limits.JointLimitSet, "
                          "Macchietto 2008, §6.2), built by JointLimitSet.compiled().")
      .def(nb::init<Eigen::Index, std::vector<BoxLimit>, std::vector<BallLimit>>(), "nv"_a,
           "boxes"_a, "balls"_a,
           "Raises ValueError naming the joint if a limit is malformed.")
      .def("errors", &errors, "q"_a,
           "JointLimitSet.errors(q): the limit violation per DoF, a new (nv,) array. "
           "IndexError if q is shorter than min_nq; ValueError naming the joint if a ball "
           "quaternion is not finite or is zero.")
      .def("ball_error", &JointLimits::ball_error, "ball"_a, "quaternion_xyzw"_a,
           "BallJointLimit.error of balls[ball] at a quaternion [x, y, z, w].")
      .def_prop_ro("nv", &JointLimits::nv)
      .def_prop_ro("min_nq", &JointLimits::min_nq)
      .def_prop_ro("boxes", &JointLimits::boxes)
      .def_prop_ro("balls", &JointLimits::balls);
}

}  // namespace poise
