#include "weighted.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/spatial.hpp>

#include "frame_point.hpp"

namespace poise {

namespace {
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr Eigen::Index kRootDofs = 6;
}  // namespace

WeightedOptimizer::WeightedOptimizer(const Model& model, std::size_t contact_count)
    : model_(model),
      q_reference_(Eigen::VectorXd::Zero(model.nq)),
      tracking_weight_(Eigen::VectorXd::Zero(model.nv)),
      tracking_b_(Eigen::VectorXd::Zero(model.nv)),
      difference_(Eigen::VectorXd::Zero(model.nv)),
      hessian_(Eigen::MatrixXd::Zero(model.nv, model.nv)),
      gradient_(Eigen::VectorXd::Zero(model.nv)),
      frame_jacobian_(Data::Matrix6x::Zero(6, model.nv)) {
  linear_ = {"linear_momentum", RowMatrix::Zero(2, model.nv), Eigen::VectorXd::Zero(2), 0.0, false};
  angular_ = {"angular_momentum", RowMatrix::Zero(3, model.nv), Eigen::VectorXd::Zero(3), 0.0,
              false};
  C_.resize(static_cast<Eigen::Index>(6 * contact_count), model.nv);
  d_.resize(static_cast<Eigen::Index>(6 * contact_count));
  for (Polygon* polygon : {&polygon_, &admissible_, &polygon_scratch_.sorted,
                           &polygon_scratch_.vertices}) {
    polygon->reserve(64);
  }
  polygon_scratch_.lines.reserve(64);
  report_.linear_momentum_rate_desired.setConstant(kNaN);
  report_.angular_momentum_rate_desired.setConstant(kNaN);
}

void WeightedOptimizer::add_rows(const Rows& rows) {
  // M += Aᵀ W A, u += Aᵀ W b (solvers.kkt.build_weighted_problem).
  hessian_.noalias() += rows.weight * (rows.A.transpose() * rows.A);
  gradient_.noalias() += rows.weight * (rows.A.transpose() * rows.b);
}

void WeightedOptimizer::tracking(const Model& model, const Eigen::Ref<const Eigen::VectorXd>& q,
                                 const Eigen::Ref<const Eigen::VectorXd>& v,
                                 const WeightedParams& p,
                                 const Eigen::Ref<const Eigen::VectorXd>& limit_errors,
                                 const Eigen::Ref<const Eigen::VectorXd>& q_ref,
                                 const Eigen::Ref<const Eigen::VectorXd>& v_ref,
                                 const Eigen::Ref<const Eigen::VectorXd>& a_ref) {
  // tasks.tracking.TrackingTask: the root position is left to the balance objectives.
  q_reference_ = q_ref;
  q_reference_.head<3>() = q.head<3>();
  pinocchio::difference(model, q, q_reference_, difference_);
  // q̈_des = k'_s (q_ref ⊖ q) + k'_d (v_ref − v) + a_ref, k' = k + l e (eq. 5.3, 6.5–6.6).
  const Eigen::Index nv = model.nv;
  for (Eigen::Index i = 0; i < nv; ++i) {
    const double stiffness = p.stiffness + p.joint_limit_stiffness * limit_errors(i);
    const double damping = p.damping + p.joint_limit_damping * limit_errors(i);
    tracking_b_(i) = stiffness * difference_(i) + damping * (v_ref(i) - v(i)) + a_ref(i);
  }
  // W_t²: 0 on the root position, the root orientation's own weight, β_t × joint weights.
  tracking_weight_.head<3>().setZero();
  tracking_weight_.segment<3>(3).setConstant(p.weight_root_orientation);
  tracking_weight_.tail(nv - kRootDofs) = p.weight_tracking * p.joint_weights;
  hessian_.diagonal() += tracking_weight_;
  gradient_.array() += tracking_weight_.array() * tracking_b_.array();
}

void WeightedOptimizer::support_polygon(const Terms& terms, const std::vector<bool>& supports,
                                        Polygon& hull) {
  Eigen::Index count = 0;
  for (std::size_t c = 0; c < supports.size(); ++c) {
    if (supports[c]) count += terms.contacts[c].position_points_in_world.rows();
  }
  supporting_points_.resize(count, 3);  // no allocation once the largest has been seen
  Eigen::Index row = 0;
  for (std::size_t c = 0; c < supports.size(); ++c) {
    if (!supports[c]) continue;
    const Points& points = terms.contacts[c].position_points_in_world;
    supporting_points_.middleRows(row, points.rows()) = points;
    row += points.rows();
  }
  if (count == 0) {
    hull.clear();
    return;
  }
  poise::support_polygon(supporting_points_, polygon_scratch_, hull);
}

void WeightedOptimizer::linear_momentum(const Terms& terms,
                                        const Eigen::Ref<const Eigen::VectorXd>& v,
                                        const std::vector<bool>& supports,
                                        const WeightedParams& p, double gravity) {
  // tasks.linear_momentum.LinearMomentumTask (eq. 5.9–5.10).
  report_.linear_momentum_rate_desired.setConstant(kNaN);
  linear_.present = false;
  std::size_t count = 0;
  for (bool on : supports) count += on ? 1 : 0;
  const double weight = p.weight_linear_momentum;
  if (count == 0 || weight <= 0) return;
  const double mass = terms.total_mass;
  Eigen::Vector3d support_velocity = Eigen::Vector3d::Zero();
  Eigen::Vector3d com_desired = Eigen::Vector3d::Zero();
  double mu = kInf;
  for (std::size_t c = 0; c < supports.size(); ++c) {
    if (!supports[c]) continue;
    support_velocity.noalias() += terms.contacts[c].support_jacobian.topRows<3>() * v;
    com_desired += terms.position_contact_frames_in_world.row(static_cast<Eigen::Index>(c)).transpose();
    mu = std::min(mu, p.friction_coefficients(static_cast<Eigen::Index>(c)));
  }
  support_velocity /= static_cast<double>(count);
  com_desired /= static_cast<double>(count);
  com_desired.head<2>() += p.com_offset_xy;
  const Eigen::Vector3d& com = terms.position_com_in_world;
  // L̇_des = k_s m (c_des − c) + k_d (m ṡ − L) on x, y (eq. 5.9, the damping sign).
  Eigen::Vector3d rate;
  for (int axis = 0; axis < 2; ++axis) {
    rate(axis) = p.momentum_stiffness * mass * (com_desired(axis) - com(axis)) +
                 p.momentum_damping * (mass * support_velocity(axis) - terms.linear_momentum(axis));
  }
  rate(2) = kNaN;
  // features.linear_momentum.admissible_linear_momentum_rate.
  admissible_cop_polygon(polygon_, p.cop_margin, polygon_scratch_, admissible_);
  const double lever = (com(2) - p.ground_height) / (mass * gravity);
  if (gravity > 0.0 && !admissible_.empty() && 0.0 < lever && lever < kInf) {
    const Eigen::Vector2d cop(com(0) - lever * rate(0), com(1) - lever * rate(1));
    const Eigen::Vector2d closest = closest_point_in_polygon(cop, admissible_);
    const double grip = mu / std::sqrt(2.0) * mass * gravity;
    rate(0) = std::min(std::max((com(0) - closest(0)) / lever, -grip), grip);
    rate(1) = std::min(std::max((com(1) - closest(1)) / lever, -grip), grip);
  }
  report_.linear_momentum_rate_desired = rate;
  // Rows R / m_T toward (L̇_des − r_bias) / m_T on x, y (eq. 5.10).
  linear_.A = terms.R.topRows<2>() / mass;
  linear_.b = (rate - terms.r_bias).head<2>() / mass;
  linear_.weight = weight;
  linear_.present = true;
  add_rows(linear_);
}

void WeightedOptimizer::angular_momentum(const Terms& terms, const std::vector<bool>& supports,
                                         const WeightedParams& p,
                                         const Eigen::Ref<const RowMatrix>& wrenches) {
  // tasks.angular_momentum.CopWeightedAngularMomentumTask (eq. 5.15–5.17).
  Eigen::Vector3d cop, cmp;
  if (wrenches.rows() == 0) {
    cop.setConstant(kNaN);
    cmp.setConstant(kNaN);
  } else {
    ground_reference_points(terms.position_contact_frames_in_world, terms.position_com_in_world,
                            wrenches, supports, p.ground_height, cop, cmp);
  }
  const double distance = (cop - cmp).head<2>().norm();
  const double effective = p.weight_angular_momentum +
                           (std::isfinite(distance) ? p.angular_momentum_gain * distance : 0.0);
  report_.angular_momentum_weight = effective;
  angular_.present = false;
  if (effective <= 0) {
    report_.angular_momentum_rate_desired.setConstant(kNaN);
    return;
  }
  const Eigen::Vector3d rate = -p.angular_momentum_damping * terms.angular_momentum;
  report_.angular_momentum_rate_desired = rate;
  angular_.A = terms.S / terms.total_mass;
  angular_.b = (rate - terms.s_bias) / terms.total_mass;
  angular_.weight = effective;
  angular_.present = true;
  add_rows(angular_);
}

void WeightedOptimizer::point(const Model& model, Data& data, const PointTarget& target,
                              Rows& rows) {
  // tasks.point.PointTask, dynamics.point_kinematics (App. C, eq. C.3, C.7; eq. 6.1–6.3).
  constexpr auto kWorldAligned = pinocchio::LOCAL_WORLD_ALIGNED;
  frame_jacobian_.setZero();
  pinocchio::getFrameJacobian(model, data, target.frame_id, kWorldAligned, frame_jacobian_);
  const pinocchio::Motion velocity =
      pinocchio::getFrameVelocity(model, data, target.frame_id, kWorldAligned);
  const pinocchio::Motion drift =
      pinocchio::getFrameClassicalAcceleration(model, data, target.frame_id, kWorldAligned);
  const pinocchio::SE3& placement = data.oMf[target.frame_id];
  const Eigen::Vector3d r = placement.rotation() * target.offset_in_frame;
  const Eigen::Vector3d omega = velocity.angular();
  const Eigen::Vector3d position = placement.translation() + r;
  const Eigen::Vector3d point_velocity = velocity.linear() - pinocchio::skew(r) * omega;
  Eigen::Vector3d point_drift;
  frame_point_rows(frame_jacobian_, drift, omega, r, rows.A, point_drift);
  rows.b = target.stiffness * (target.target_position_in_world - position) +
           target.damping * (target.target_velocity_in_world - point_velocity) - point_drift;
  rows.weight = target.weight;
  rows.present = true;
}

bool WeightedOptimizer::optimize(
    const Terms& terms, Data& data, const Eigen::Ref<const Eigen::VectorXd>& q,
    const Eigen::Ref<const Eigen::VectorXd>& v, const std::vector<bool>& supports,
    const WeightedParams& params, const std::vector<PointTarget>& points,
    const Eigen::Ref<const Eigen::VectorXd>& limit_errors,
    const Eigen::Ref<const Eigen::VectorXd>& q_ref, const Eigen::Ref<const Eigen::VectorXd>& v_ref,
    const Eigen::Ref<const Eigen::VectorXd>& a_ref, const Eigen::Ref<const RowMatrix>& wrenches,
    double gravity, Eigen::Ref<Eigen::VectorXd> x) {
  support_polygon(terms, supports, polygon_);
  hessian_.setZero();
  gradient_.setZero();
  tracking(model_, q, v, params, limit_errors, q_ref, v_ref, a_ref);
  linear_momentum(terms, v, supports, params, gravity);
  angular_momentum(terms, supports, params, wrenches);
  if (points_.size() < points.size()) {
    points_.resize(points.size(), Rows{"", RowMatrix::Zero(3, model_.nv), Eigen::VectorXd::Zero(3)});
  }
  point_count_ = points.size();
  for (std::size_t i = 0; i < points.size(); ++i) {
    points_[i].name = "point:" + points[i].name;  // reuses its capacity: same names each tick
    point(model_, data, points[i], points_[i]);
    add_rows(points_[i]);
  }
  // The support equality J_sup q̈ = −J̇_sup q̇ (eq. 5.1; constraints.support).
  Eigen::Index rows = 0;
  for (std::size_t c = 0; c < supports.size(); ++c) {
    if (!supports[c]) continue;
    C_.middleRows<6>(rows) = terms.contacts[c].support_jacobian;
    d_.segment<6>(rows) = -terms.contacts[c].support_drift;
    rows += 6;
  }
  return kkt_.solve(hessian_, gradient_, C_.topRows(rows), d_.head(rows),
                    params.objective_gain_bound, params.constraint_gain_bound, x, report_.kkt);
}

void WeightedOptimizer::residuals(const Eigen::Ref<const Eigen::VectorXd>& x,
                                  std::vector<std::pair<std::string, double>>& out) const {
  out.clear();
  // Objective.residual: ‖√w (A x − b)‖.
  const double tracking =
      (tracking_weight_.array().sqrt() * (x - tracking_b_).array()).matrix().norm();
  out.emplace_back("tracking", tracking);
  const auto weighted = [&x](const Rows& rows) {
    return std::sqrt(rows.weight) * (rows.A * x - rows.b).norm();
  };
  if (linear_.present) out.emplace_back(linear_.name, weighted(linear_));
  if (angular_.present) out.emplace_back(angular_.name, weighted(angular_));
  for (std::size_t i = 0; i < point_count_; ++i) out.emplace_back(points_[i].name, weighted(points_[i]));
}

}  // namespace poise
