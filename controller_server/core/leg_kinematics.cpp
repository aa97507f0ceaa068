#include "leg_kinematics.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>

#include "lie.hpp"

namespace poise {

GroundedLegKinematics::GroundedLegKinematics(std::shared_ptr<const Model> model,
                                             std::vector<pinocchio::FrameIndex> frame_ids,
                                             std::vector<Points> corners_in_frame,
                                             double grounded_tolerance_m)
    : model_(std::move(model)),
      frame_ids_(std::move(frame_ids)),
      corners_in_frame_(std::move(corners_in_frame)),
      tolerance_m_(grounded_tolerance_m),
      data_(*model_),
      frame_jacobian_(Data::Matrix6x::Zero(6, model_->nv)) {
  if (frame_ids_.size() != corners_in_frame_.size()) {
    throw std::invalid_argument("one (k, 3) corners array per contact frame id is needed");
  }
  Eigen::Index most = 0;
  for (std::size_t c = 0; c < frame_ids_.size(); ++c) {
    if (frame_ids_[c] >= static_cast<pinocchio::FrameIndex>(model_->nframes)) {
      throw std::invalid_argument("contact frame id " + std::to_string(frame_ids_[c]) +
                                  " is not below nframes = " + std::to_string(model_->nframes));
    }
    const Eigen::Index count = corners_in_frame_[c].rows();
    if (count < 1 || count > 32) {
      throw std::invalid_argument("a contact has 1 to 32 corners, got " + std::to_string(count));
    }
    most = std::max(most, count);
  }
  corner_positions_ = Points::Zero(most, 3);
  corner_offsets_ = Points::Zero(most, 3);
}

void GroundedLegKinematics::normalize(Eigen::Ref<Eigen::VectorXd> q) const {
  pinocchio::normalize(*model_, q);
}

void GroundedLegKinematics::compute(const Eigen::Ref<const Eigen::VectorXd>& q,
                                    const Eigen::Matrix3d& rotation_base_in_world,
                                    const CornerSet* previous, std::vector<ContactPoint>& points,
                                    std::vector<CornerSet>& used) {
  const Model& model = *model_;
  const Eigen::Index joints = model.nv - 6;
  // Forward kinematics and the joint Jacobians data.J; below, the contact frames' placements
  // (the same products as updateFramePlacements, for those frames only).
  pinocchio::computeJointJacobians(model, data_, q);
  const Eigen::RowVector3d up = rotation_base_in_world.row(2);  // world z of base vectors

  for (std::size_t c = 0; c < frame_ids_.size(); ++c) {
    const pinocchio::SE3& placement = pinocchio::updateFramePlacement(model, data_, frame_ids_[c]);
    frame_jacobian_.setZero();
    pinocchio::getFrameJacobian(model, data_, frame_ids_[c], pinocchio::LOCAL_WORLD_ALIGNED,
                                frame_jacobian_);
    const Points& corners = corners_in_frame_[c];
    const Eigen::Index count = corners.rows();
    // Each corner p_f + R_f r (its Jacobian, J_lin − [R_f r]× J_ang, is linear in R_f r: the
    // centroid's below is that of the corners' mean offset).
    double lowest = 0.0;
    double heights[32];
    for (Eigen::Index i = 0; i < count; ++i) {
      corner_offsets_.row(i) = (placement.rotation() * corners.row(i).transpose()).transpose();
      corner_positions_.row(i) = placement.translation().transpose() + corner_offsets_.row(i);
      heights[i] = up.dot(corner_positions_.row(i));
      // np.min: a NaN anywhere is the minimum.
      if (i == 0 || std::isnan(heights[i])) {
        lowest = heights[i];
      } else if (!std::isnan(lowest)) {
        lowest = std::min(lowest, heights[i]);
      }
    }
    // A foot keeps its previous corners while they all stay within twice the tolerance
    // (a change costs the filter that foot's history); else those within the tolerance.
    // A NaN height is within neither: no corner, and a NaN point the filter refuses.
    CornerSet chosen = 0;
    const CornerSet kept = previous == nullptr ? 0 : previous[c];
    bool keep = kept != 0;
    for (Eigen::Index i = 0; i < count && keep; ++i) {
      if ((kept >> i & 1U) && !(heights[i] - lowest <= 2 * tolerance_m_)) keep = false;
    }
    if (keep) {
      chosen = kept;
    } else {
      for (Eigen::Index i = 0; i < count; ++i) {
        if (heights[i] - lowest <= tolerance_m_) chosen |= CornerSet{1} << i;
      }
    }
    // Their centroid and its Jacobian J_lin − [r̄]× J_ang, r̄ their mean offset from the frame
    // (np.mean: sum, then divide; the mean of the corners' Jacobians up to rounding).
    ContactPoint& point = points[c];
    Eigen::Vector3d offset = Eigen::Vector3d::Zero();
    point.position_in_base.setZero();
    int n = 0;
    for (Eigen::Index i = 0; i < count; ++i) {
      if (!(chosen >> i & 1U)) continue;
      point.position_in_base += corner_positions_.row(i).transpose();
      offset += corner_offsets_.row(i).transpose();
      ++n;
    }
    if (n == 0) {
      point.position_in_base.setConstant(std::numeric_limits<double>::quiet_NaN());
      point.jacobian.setConstant(std::numeric_limits<double>::quiet_NaN());
    } else {
      point.position_in_base /= n;
      offset /= n;
      // (noalias: a product in an expression would be a heap temporary of nv − 6 columns)
      point.jacobian = frame_jacobian_.topRightCorner(3, joints);
      point.jacobian.noalias() -= lie::skew(offset) * frame_jacobian_.bottomRightCorner(3, joints);
    }
    used[c] = chosen;
  }
}

}  // namespace poise
