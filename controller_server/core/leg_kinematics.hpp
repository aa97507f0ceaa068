// The leg-kinematics measurement of the base estimator, as estimation/leg_kinematics.py's
// grounded_leg_kinematics: one point per contact, the centroid of its sole corners on the
// ground, in the base frame, with its Jacobian with respect to the joint positions.
//
// Hartley et al. 2020 (forward kinematic measurements) and Bloesch et al., RSS 2012
// (kinematic measurement model): s(α) and J(α) = ∂s/∂α, which maps encoder noise to
// measurement noise, Cov[s] = J Σ_α Jᵀ. With the free flyer at the identity the world frame
// is the base frame, so Pinocchio's world-aligned frame Jacobians are the base-frame ones.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "dynamics_core.hpp"

namespace poise {

// The corners of one contact in use, bit i for corner i (MAX_POINTS_PER_CONTACT is 32): the
// index tuple of grounded_leg_kinematics, which is always sorted.
using CornerSet = std::uint32_t;

// One contact's point in the base frame and its (3, nv − 6) joint Jacobian.
struct ContactPoint {
  Eigen::Vector3d position_in_base;
  Eigen::Matrix<double, 3, Eigen::Dynamic> jacobian;
};

// One robot's contacts (each a frame and its sole corners) and a workspace of its own
// (pinocchio Data, buffers allocated at construction).
class GroundedLegKinematics {
 public:
  // `corners_in_frame[c]`: contact c's (k, 3) sole corners in its frame `frame_ids[c]`.
  // Throws std::invalid_argument for a frame id out of range or more than 32 corners.
  GroundedLegKinematics(std::shared_ptr<const Model> model,
                        std::vector<pinocchio::FrameIndex> frame_ids,
                        std::vector<Points> corners_in_frame, double grounded_tolerance_m);

  // q = [0, 0, 0, 0, 0, 0, 1, joint_position] (Pinocchio order), normalised in place
  // (pin.normalize: ball joints' quaternions).
  void normalize(Eigen::Ref<Eigen::VectorXd> q) const;

  // grounded_leg_kinematics at q (normalised, base at the identity): the corners within the
  // tolerance of each foot's lowest corner in the world's vertical (from
  // `rotation_base_in_world`), or the foot's `previous` corners while they all stay within
  // twice that (`previous` null: none). Writes `points` and `used` (one per contact).
  void compute(const Eigen::Ref<const Eigen::VectorXd>& q,
               const Eigen::Matrix3d& rotation_base_in_world, const CornerSet* previous,
               std::vector<ContactPoint>& points, std::vector<CornerSet>& used);

  std::size_t contact_count() const { return frame_ids_.size(); }
  const Model& model() const { return *model_; }

 private:
  std::shared_ptr<const Model> model_;
  std::vector<pinocchio::FrameIndex> frame_ids_;
  std::vector<Points> corners_in_frame_;
  double tolerance_m_;
  Data data_;
  Data::Matrix6x frame_jacobian_;   // (6, nv) scratch
  Points corner_positions_;         // (k, 3) of one contact, scratch
  Points corner_offsets_;           // (k, 3): R_f r, scratch
};

}  // namespace poise
