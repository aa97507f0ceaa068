// Soft joint-limit errors of one tick (Macchietto 2008, §6.2, eq. 6.4–6.6), in C++.
//
// The executable specification is Python: JointLimitSet.errors and BallJointLimit.error
// (controller_server/features/joint_limits.py), with the swing–twist split and the swing
// cones of controller_server/features/swing_twist.py. Python still builds the limits
// (default_joint_limits, SwingCone.regular) and hands them over as plain data
// (JointLimitSet.compiled()); this computes, per tick, each DoF's violation e that raises
// the tracking gains k'_s = k_s + l_s e, k'_d = k_d + l_d e (eq. 6.5–6.6).
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace poise {

// (k, 3) unit vectors, one per row (C order, as numpy gives them).
using UnitVectors = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

// A 1-DoF joint's box [lower, upper] on its coordinate: rad (revolute) or m (prismatic).
// Mirrors RevoluteJointLimit.
struct BoxLimit {
  std::string name;
  Eigen::Index idx_q = 0;  // the coordinate q[idx_q]
  Eigen::Index idx_v = 0;  // its DoF v[idx_v]
  double lower = 0.0;
  double upper = 0.0;
};

// A ball joint's swing cone on the bone axis and twist interval about it. Mirrors
// BallJointLimit and its SwingCone (the fields are theirs, as Python computed them).
struct BallLimit {
  std::string name;
  Eigen::Index idx_q = 0;  // quaternion [x, y, z, w] at q[idx_q : idx_q + 4]
  Eigen::Index idx_v = 0;  // its 3 DoFs at v[idx_v : idx_v + 3]
  Eigen::Vector3d bone_axis_in_parent = Eigen::Vector3d::Zero();  // a, unit
  UnitVectors face_normals_in_parent;  // (k, 3) outward normals, k = 0 (no swing limit) or ≥ 3
  UnitVectors edges_in_parent;         // (k, 3) edge rays of a convex cone; (0, 3) if reflex
  bool reflex = false;                 // the cone is the complement of a convex one
  double twist_lower_rad = 0.0;        // α_l
  double twist_upper_rad = 0.0;        // α_u > α_l
};

// A robot's joint limits (JointLimitSet): validated once at construction, then errors(q)
// per tick, allocating nothing and keeping no state (const: callable from several threads).
class JointLimits {
 public:
  // Throws std::invalid_argument naming the joint if a limit is malformed (an index
  // outside nv, a cone with 1 or 2 faces, edges that do not match the faces, a zero axis,
  // twist_lower_rad >= twist_upper_rad).
  JointLimits(Eigen::Index nv, std::vector<BoxLimit> boxes, std::vector<BallLimit> balls);

  // JointLimitSet.errors: the limit violation per DoF (rad, or m for prismatic joints),
  // `errors_per_dof` of size nv. Each ball joint's e_axis + e_twist goes on its 3 DoFs, a
  // box's violation on its DoF, 0 elsewhere (the free-flyer root). As in Python, NaN in a
  // box coordinate gives NaN on its DoF; a ball quaternion that is not finite, or too short
  // to normalise, throws std::invalid_argument naming the joint (Python raises too).
  // Throws std::out_of_range if q has fewer than min_nq() entries, std::invalid_argument
  // if errors_per_dof does not have nv.
  void errors(const Eigen::Ref<const Eigen::VectorXd>& q,
              Eigen::Ref<Eigen::VectorXd> errors_per_dof) const;

  // BallJointLimit.error: e_axis + e_twist of one ball joint at quaternion [x, y, z, w].
  double ball_error(std::size_t ball, const Eigen::Vector4d& quaternion_xyzw) const;

  Eigen::Index nv() const { return nv_; }
  // The shortest q that holds every limited coordinate.
  Eigen::Index min_nq() const { return min_nq_; }
  const std::vector<BoxLimit>& boxes() const { return boxes_; }
  const std::vector<BallLimit>& balls() const { return balls_; }

 private:
  Eigen::Index nv_;
  Eigen::Index min_nq_ = 0;
  std::vector<BoxLimit> boxes_;
  std::vector<BallLimit> balls_;
  // Each ball's bone axis as swing_twist's _unit(axis) rescales it (the twist's axis).
  std::vector<Eigen::Vector3d> twist_axes_;
};

}  // namespace poise
