// A point fixed to a frame, from the frame's world-aligned Jacobian, twist and drift
// (Macchietto 2008, App. C; dynamics._points_on_frame): with p = o + r, r in world axes,
//   J_p = J_v − [r]× J_ω                                  (eq. C.3)
//   p̈ at q̈ = 0: a_o − [r]× α + ω × (ω × r)               (eq. C.7)
// Shared by the sole points (DynamicsCore) and the point targets (WeightedOptimizer).
#pragma once

#include <Eigen/Core>

#include <pinocchio/multibody.hpp>
#include <pinocchio/spatial.hpp>

namespace poise {

// Writes the point's (3, nv) Jacobian rows into `jacobian` and its drift into `drift`.
template <typename JacobianRows, typename DriftOut>
void frame_point_rows(const pinocchio::Data::Matrix6x& frame_jacobian,
                      const pinocchio::Motion& frame_drift, const Eigen::Vector3d& omega,
                      const Eigen::Vector3d& r, JacobianRows&& jacobian, DriftOut&& drift) {
  const Eigen::Matrix3d r_cross = pinocchio::skew(r);  // [r]× w = r × w
  jacobian = frame_jacobian.topRows<3>() - r_cross * frame_jacobian.bottomRows<3>();
  // ω × (ω × r) = ω (ω · r) − |ω|² r
  drift = frame_drift.linear() - r_cross * frame_drift.angular() + omega * omega.dot(r) -
          omega.squaredNorm() * r;
}

}  // namespace poise
