// Soft joint-limit errors (Macchietto 2008, §6.2, eq. 6.4–6.6): see joint_limits.hpp.
//
// Each function mirrors one Python function, named in its comment, step by step, so that
// the two agree to rounding. Two steps of the specification are ill conditioned: the
// distance to a convex cone's edge ray, acos(e · d) near 1, and the twist near a half turn
// about an axis ⊥ the bone (eq. 6.4's singularity). There one ulp of a dot product moves
// the error by up to 1.5e-8 rad. So where a dot product gives a value (not only a yes/no),
// it is rounded as numpy's: numpy's `a @ b` calls OpenBLAS, whose kernels on this machine
// (scipy-openblas 0.3.31, AVX-512) sum with fused multiply-adds in the orders of
// dot_like_numpy and row_dot_like_numpy. With them the two agree to 9e-16 (numpy's own
// arctan2 and arccos against glibc's), with plain sums to 1.5e-8; a BLAS that sums
// otherwise stays within the agreement test's allowance. The plain arithmetic is compiled
// with -ffp-contract=off (CMakeLists.txt), as numpy rounds every product and sum.
#include "joint_limits.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

namespace poise {

namespace {

constexpr double kPi = 3.141592653589793;  // math.pi
constexpr double kTiny = 1e-12;            // swing_twist._TINY
constexpr double kDegenerateSwing = 1e-9;  // swing_twist._DEGENERATE_SWING
constexpr double kOnConeTolerance = 1e-12;  // SwingCone.violation's foot-on-cone test

// numpy's `a @ b` for float64 vectors (OpenBLAS ddot): a₀b₀, then fma in index order.
double dot_like_numpy(const double* a, const double* b, int size) {
  double sum = a[0] * b[0];
  for (int i = 1; i < size; ++i) sum = std::fma(a[i], b[i], sum);
  return sum;
}

// One entry of numpy's `(k, 3) @ (3,)` (OpenBLAS dgemv, transposed kernel): another order.
double row_dot_like_numpy(const double* row, const double* v) {
  return std::fma(row[2], v[2], std::fma(row[0], v[0], row[1] * v[1]));
}

// swing_twist._unit: `vector / ‖vector‖`; false where Python raises (‖vector‖ not finite
// or below _TINY).
template <int Size>
bool unit_like_numpy(const double* vector, double* unit) {
  const double norm = std::sqrt(dot_like_numpy(vector, vector, Size));
  if (!std::isfinite(norm) || norm < kTiny) return false;
  for (int i = 0; i < Size; ++i) unit[i] = vector[i] / norm;
  return true;
}

// controller_server.math.spatial.cross on 3-vectors.
void cross(const double* a, const double* b, double* out) {
  out[0] = a[1] * b[2] - a[2] * b[1];
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}

// numpy.maximum: NaN if either is NaN.
double nan_propagating_max(double a, double b) { return (a >= b || std::isnan(a)) ? a : b; }

// joint_limits._box_violation, Python's max(lower − value, 0, value − upper).
double box_violation(double value, double lower, double upper) {
  double result = lower - value;
  if (0.0 > result) result = 0.0;
  if (value - upper > result) result = value - upper;
  return result;
}

std::string joint_context(const std::string& name) { return "joint '" + name + "': "; }

[[noreturn]] void throw_bad_quaternion(const BallLimit& ball, const double* quaternion_xyzw) {
  std::ostringstream message;
  message.precision(17);
  message << joint_context(ball.name)
          << "quaternion_xyzw must be finite and non-zero, got [" << quaternion_xyzw[0] << ", "
          << quaternion_xyzw[1] << ", " << quaternion_xyzw[2] << ", " << quaternion_xyzw[3]
          << "]";
  throw std::invalid_argument(message.str());
}

// How numpy rounds a face normal's projection n · a' (see the top of this file).
enum class Rounding {
  kMatVec,  // `normals @ direction` (SwingCone.contains_unit): OpenBLAS dgemv
  kEinsum,  // einsum("bsk,bk->bs") (swing_twist.cones_contain_units): (n₀a₀ + n₂a₂) + n₁a₁
};

double projection_like_numpy(const double* normal, const double* direction, Rounding rounding) {
  if (rounding == Rounding::kMatVec) return row_dot_like_numpy(normal, direction);
  return (normal[0] * direction[0] + normal[2] * direction[2]) + normal[1] * direction[1];
}

struct ConeTest {
  bool contains;
  bool near_tiny;  // some n · a' was within kBand of _TINY
};

// SwingCone.contains_unit: a' · n_i ≤ 0 for every face (convex), for some face (reflex),
// with _TINY of slack (Macchietto 2008, §6.2; the thesis's "< π" is a typo for "≤ 0").
// As numpy's max / min, a NaN projection means "not contained".
//
// Where a' · n_i is within kBand of _TINY the projection is rounded as numpy's, so that
// the yes/no is the Python's there (just outside, the exact error is ~_TINY, not 0).
// Elsewhere plain arithmetic decides the same at a third of the cost (std::fma is a call
// on the baseline x86-64 this builds for): the roundings of unit n · unit a' differ by a
// few 1e-16.
constexpr double kBand = 1e-14;

ConeTest contains_unit(const BallLimit& ball, const double* direction, Rounding rounding) {
  const UnitVectors& normals = ball.face_normals_in_parent;
  if (normals.rows() == 0) return {true, false};
  bool every = true, some = false, nan = false, near_tiny = false;
  for (Eigen::Index i = 0; i < normals.rows(); ++i) {
    const double* n = normals.row(i).data();
    double projection = n[0] * direction[0] + n[1] * direction[1] + n[2] * direction[2];
    if (std::abs(projection - kTiny) < kBand) {
      projection = projection_like_numpy(n, direction, rounding);
      near_tiny = true;
    }
    const bool inside = projection <= kTiny;
    every = every && inside;
    some = some || inside;
    nan = nan || std::isnan(projection);
  }
  return {ball.reflex ? (some && !nan) : every, near_tiny};
}

// The cheap test that e_axis and e_twist are both 0: BallJointLimit._within, in the
// Python's scalar arithmetic. Its answer only decides whether the exact error runs (0
// inside, continuous across the boundary). JointLimitSet.errors runs the same test on all
// joints at once (_balls_within), rounded otherwise, before _within: where the two
// roundings can disagree (a' · n_i ≈ _TINY) that one is taken too, inside if either says
// so, as in Python. A zero quaternion throws (Python's ZeroDivisionError); NaN gives
// false, and the exact error then throws.
bool within(const BallLimit& ball, const double* quaternion_xyzw) {
  double x = quaternion_xyzw[0], y = quaternion_xyzw[1], z = quaternion_xyzw[2],
         w = quaternion_xyzw[3];
  const double norm = std::sqrt(x * x + y * y + z * z + w * w);
  if (norm == 0.0) throw_bad_quaternion(ball, quaternion_xyzw);
  x = x / norm;
  y = y / norm;
  z = z / norm;
  w = w / norm;
  const double ax = ball.bone_axis_in_parent[0], ay = ball.bone_axis_in_parent[1],
               az = ball.bone_axis_in_parent[2];
  // Twist angle about a: 2 atan2(u · a, w), wrapped to (−π, π].
  double twist = 2.0 * std::atan2(x * ax + y * ay + z * az, w);
  if (twist > kPi) {
    twist = twist - 2 * kPi;
  } else if (twist <= -kPi) {
    twist = twist + 2 * kPi;
  }
  if (!(ball.twist_lower_rad <= twist && twist <= ball.twist_upper_rad)) return false;
  // a' = a + w t + u × t with t = 2 u × a (rotation of the bone axis).
  const double tx = 2 * (y * az - z * ay), ty = 2 * (z * ax - x * az),
               tz = 2 * (x * ay - y * ax);
  const double bone[3] = {ax + w * tx + y * tz - z * ty, ay + w * ty + z * tx - x * tz,
                          az + w * tz + x * ty - y * tx};
  const ConeTest test = contains_unit(ball, bone, Rounding::kMatVec);
  if (test.contains || !test.near_tiny) return test.contains;
  // _balls_within's a' = (a + w t) + (u × t), and its einsum.
  const double bone_at_once[3] = {ax + w * tx + (y * tz - z * ty), ay + w * ty + (z * tx - x * tz),
                                  az + w * tz + (x * ty - y * tx)};
  return contains_unit(ball, bone_at_once, Rounding::kEinsum).contains;
}

// swing_twist.rotate: q v q⁻¹ for a unit quaternion, as v + w t + u × t with t = 2 u × v.
void rotate(const double* unit_quaternion_xyzw, const Eigen::Vector3d& vector, double* out) {
  const double* u = unit_quaternion_xyzw;
  double doubled_cross[3], second_cross[3];
  cross(u, vector.data(), doubled_cross);
  for (double& entry : doubled_cross) entry = 2.0 * entry;
  cross(u, doubled_cross, second_cross);
  for (int i = 0; i < 3; ++i) {
    out[i] = vector[i] + u[3] * doubled_cross[i] + second_cross[i];
  }
}

// swing_twist._angle_to_plane: atan2(d · n, ‖d − (d · n) n‖), exact near π/2.
double angle_to_plane(const double* direction, const double* normal, double projection) {
  double in_plane[3];
  for (int i = 0; i < 3; ++i) in_plane[i] = direction[i] - projection * normal[i];
  return std::atan2(projection, std::sqrt(dot_like_numpy(in_plane, in_plane, 3)));
}

// SwingCone.violation: e_axis = acos(a' · a'_pr) (Macchietto 2008, §6.2), the angle from
// the bone direction a' to the nearest allowed direction a'_pr on the cone's boundary.
double cone_violation(const BallLimit& ball, const double* bone_direction) {
  double d[3];
  if (!unit_like_numpy<3>(bone_direction, d)) {  // not from a finite unit quaternion
    throw std::invalid_argument(joint_context(ball.name) + "the bone direction is not finite");
  }
  const UnitVectors& normals = ball.face_normals_in_parent;
  if (normals.rows() == 0) return 0.0;
  double d_for_contains[3];  // SwingCone.contains normalises d once more
  unit_like_numpy<3>(d, d_for_contains);
  if (contains_unit(ball, d_for_contains, Rounding::kMatVec).contains) return 0.0;
  const Eigen::Index faces = normals.rows();
  if (ball.reflex) {
    // d is inside the convex forbidden cone: its nearest boundary point is on the nearest
    // face plane (the face of least d · n_i, the first of equals as numpy's argmin).
    Eigen::Index face = 0;
    double least = row_dot_like_numpy(normals.row(0).data(), d);
    for (Eigen::Index i = 1; i < faces; ++i) {
      const double projection = row_dot_like_numpy(normals.row(i).data(), d);
      if (projection < least) {
        face = i;
        least = projection;
      }
    }
    return angle_to_plane(d, normals.row(face).data(), least);
  }
  // Outside a convex cone the nearest point is on an edge ray, or it is the foot of the
  // perpendicular on a face that d is outside of, if that foot is in the cone.
  // min_i acos(clip(e_i · d)) is acos of the largest e_i · d (acos decreases).
  double closest_edge = -std::numeric_limits<double>::infinity();
  for (Eigen::Index i = 0; i < ball.edges_in_parent.rows(); ++i) {
    const double cosine = row_dot_like_numpy(ball.edges_in_parent.row(i).data(), d);
    closest_edge = std::max(closest_edge, cosine);
  }
  double nearest = std::acos(std::clamp(closest_edge, -1.0, 1.0));
  Eigen::Index face = -1;
  double face_projection = 0.0;
  for (Eigen::Index i = 0; i < faces; ++i) {
    const double* n = normals.row(i).data();
    const double projection = row_dot_like_numpy(n, d);
    if (!(projection > 0.0)) continue;
    double foot[3];
    for (int k = 0; k < 3; ++k) foot[k] = d[k] - projection * n[k];
    const double foot_length = std::sqrt(foot[0] * foot[0] + foot[1] * foot[1] + foot[2] * foot[2]);
    if (!(foot_length > kTiny)) continue;
    double farthest_side = -std::numeric_limits<double>::infinity();
    for (Eigen::Index j = 0; j < faces; ++j) {
      const double* m = normals.row(j).data();
      farthest_side = std::max(farthest_side, foot[0] * m[0] + foot[1] * m[1] + foot[2] * m[2]);
    }
    const bool on_cone = farthest_side <= kOnConeTolerance * foot_length;
    if (on_cone && (face < 0 || projection < face_projection)) {
      face = i;
      face_projection = projection;
    }
  }
  if (face >= 0) {
    nearest = std::min(nearest, angle_to_plane(d, normals.row(face).data(), face_projection));
  }
  return nearest;
}

// swing_twist.swing_twist's twist q_t (Macchietto 2008, eq. 6.4: q = q_a q_t), then
// swing_twist.twist_angle: its angle about a in (−π, π]. `q` is unit, `axis` as _unit
// makes it. The twist is q's vector part projected on a, renormalised; at a half turn
// about an axis ⊥ a (‖(w, u · a)‖ below _DEGENERATE_SWING) it is the identity.
double twist_angle(const double* q, const Eigen::Vector3d& axis) {
  const double along = dot_like_numpy(q, axis.data(), 3);
  const double norm = std::hypot(along, q[3]);
  double twist[4];
  if (norm < kDegenerateSwing) {
    twist[0] = twist[1] = twist[2] = 0.0;
    twist[3] = q[3] >= 0.0 ? 1.0 : -1.0;
  } else {
    for (int i = 0; i < 3; ++i) twist[i] = along * axis[i] / norm;
    twist[3] = q[3] / norm;
  }
  double t[4];
  unit_like_numpy<4>(twist, t);  // ‖twist‖ = 1 to rounding: never fails
  double twist_along = dot_like_numpy(t, axis.data(), 3), w = t[3];
  if (w < 0.0) {  // q and −q are the same rotation
    twist_along = -twist_along;
    w = -w;
  }
  const double angle = 2.0 * std::atan2(twist_along, w);
  return angle <= -kPi ? kPi : angle;
}

}  // namespace

JointLimits::JointLimits(Eigen::Index nv, std::vector<BoxLimit> boxes, std::vector<BallLimit> balls)
    : nv_(nv), boxes_(std::move(boxes)), balls_(std::move(balls)) {
  if (nv_ < 0) throw std::invalid_argument("nv must be >= 0, got " + std::to_string(nv_));
  const auto check_range = [this](const std::string& name, const char* what, Eigen::Index index,
                                  Eigen::Index size, Eigen::Index bound) {
    if (index < 0 || index + size > bound) {
      throw std::invalid_argument(joint_context(name) + what + " = " + std::to_string(index) +
                                  " is outside the vector (" + std::to_string(bound) +
                                  " entries) for its " + std::to_string(size) + " entries");
    }
  };
  const Eigen::Index unbounded = std::numeric_limits<Eigen::Index>::max() / 2;
  for (const BoxLimit& box : boxes_) {
    check_range(box.name, "idx_q", box.idx_q, 1, unbounded);
    check_range(box.name, "idx_v", box.idx_v, 1, nv_);
    min_nq_ = std::max(min_nq_, box.idx_q + 1);
  }
  twist_axes_.reserve(balls_.size());
  for (const BallLimit& ball : balls_) {
    check_range(ball.name, "idx_q", ball.idx_q, 4, unbounded);
    check_range(ball.name, "idx_v", ball.idx_v, 3, nv_);
    min_nq_ = std::max(min_nq_, ball.idx_q + 4);
    Eigen::Vector3d twist_axis;
    if (!unit_like_numpy<3>(ball.bone_axis_in_parent.data(), twist_axis.data())) {
      throw std::invalid_argument(joint_context(ball.name) +
                                  "bone_axis_in_parent must be a finite non-zero 3-vector");
    }
    twist_axes_.push_back(twist_axis);
    const Eigen::Index faces = ball.face_normals_in_parent.rows();
    if (faces == 1 || faces == 2) {
      throw std::invalid_argument(joint_context(ball.name) +
                                  "a swing cone needs 0 or at least 3 faces, got " +
                                  std::to_string(faces));
    }
    if (!ball.face_normals_in_parent.allFinite() || !ball.edges_in_parent.allFinite()) {
      throw std::invalid_argument(joint_context(ball.name) +
                                  "face normals and edges must be finite");
    }
    const Eigen::Index edges = (ball.reflex || faces == 0) ? 0 : faces;
    if (ball.edges_in_parent.rows() != edges) {
      throw std::invalid_argument(
          joint_context(ball.name) + "need " + std::to_string(edges) +
          " edges (SwingCone.edges_in_parent: one per face of a convex cone, none if "
          "reflex), got " +
          std::to_string(ball.edges_in_parent.rows()));
    }
    if (!(ball.twist_lower_rad < ball.twist_upper_rad)) {
      std::ostringstream message;
      message.precision(17);
      message << joint_context(ball.name) << "need twist_lower_rad < twist_upper_rad, got "
              << ball.twist_lower_rad << " and " << ball.twist_upper_rad;
      throw std::invalid_argument(message.str());
    }
  }
}

double JointLimits::ball_error(std::size_t index, const Eigen::Vector4d& quaternion_xyzw) const {
  const BallLimit& ball = balls_.at(index);
  if (within(ball, quaternion_xyzw.data())) return 0.0;
  double q[4];
  if (!unit_like_numpy<4>(quaternion_xyzw.data(), q)) {
    throw_bad_quaternion(ball, quaternion_xyzw.data());
  }
  double bone_direction[3];  // a' = q a q⁻¹
  rotate(q, ball.bone_axis_in_parent, bone_direction);
  const double axis_error_rad = cone_violation(ball, bone_direction);
  const double twist_rad = twist_angle(q, twist_axes_[index]);
  // e_twist: the distance of φ outside [α_l, α_u] (the thesis's min(|α_l − φ|, |α_u − φ|)
  // equals it only outside the interval).
  return axis_error_rad + box_violation(twist_rad, ball.twist_lower_rad, ball.twist_upper_rad);
}

void JointLimits::errors(const Eigen::Ref<const Eigen::VectorXd>& q,
                         Eigen::Ref<Eigen::VectorXd> errors_per_dof) const {
  if (q.size() < min_nq_) {
    throw std::out_of_range("q has " + std::to_string(q.size()) + " entries, the limits read " +
                            std::to_string(min_nq_));
  }
  if (errors_per_dof.size() != nv_) {
    throw std::invalid_argument("errors_per_dof has " + std::to_string(errors_per_dof.size()) +
                                " entries, need nv = " + std::to_string(nv_));
  }
  errors_per_dof.setZero();
  // JointLimitSet.errors: the boxes as numpy's maximum(maximum(lower − q, 0), q − upper).
  for (const BoxLimit& box : boxes_) {
    const double value = q[box.idx_q];
    errors_per_dof[box.idx_v] =
        nan_propagating_max(nan_propagating_max(box.lower - value, 0.0), value - box.upper);
  }
  // Each ball joint's e_axis + e_twist on its 3 DoFs: the tracking gains of the whole
  // joint are raised (Macchietto 2008, eq. 6.5–6.6).
  for (std::size_t index = 0; index < balls_.size(); ++index) {
    const BallLimit& ball = balls_[index];
    const Eigen::Vector4d quaternion_xyzw = q.segment<4>(ball.idx_q);
    errors_per_dof.segment<3>(ball.idx_v).setConstant(ball_error(index, quaternion_xyzw));
  }
}

}  // namespace poise
