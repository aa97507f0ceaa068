#include "weighted_tick.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace poise {

namespace {
std::vector<Eigen::Index> point_counts(const DynamicsCore& core) {
  std::vector<Eigen::Index> counts;
  for (const ContactSpec& contact : core.contacts()) counts.push_back(contact.points_in_frame.rows());
  return counts;
}
}  // namespace

WeightedTick::WeightedTick(const DynamicsCore& core, Eigen::VectorXd torque_limit)
    : core_(core.clone()),
      terms_(core.model().nv, point_counts(core)),
      maps_(terms_.maps()),
      optimizer_(core_.model(), core.contacts().size()),
      inverse_dynamics_(core.model().nv, point_counts(core), std::move(torque_limit)),
      limit_errors_(Eigen::VectorXd::Zero(core.model().nv)),
      x_(Eigen::VectorXd::Zero(core.model().nv)),
      q_ref_(Eigen::VectorXd::Zero(core.model().nq)),
      zero_(Eigen::VectorXd::Zero(core.model().nv)),
      last_wrenches_(0, 6),
      gravity_(core.model().gravity.linear().norm()) {
  const auto contact_count = static_cast<Eigen::Index>(core.contacts().size());
  params.joint_weights = Eigen::VectorXd::Ones(core.model().nv - 6);
  params.friction_coefficients = Eigen::VectorXd::Ones(contact_count);
  params.reference_configuration = Eigen::VectorXd::Zero(core.model().nq);
  params.reference_configuration(6) = 1.0;
  diagnostics_.support_polygon.reserve(64);
  diagnostics_.objective_residuals.reserve(16);
}

void WeightedTick::set_limits(JointLimits limits) {
  if (limits.nv() != core_.model().nv) {
    throw std::invalid_argument("joint limits for another number of DoFs");
  }
  limits_.emplace(std::move(limits));
}

bool WeightedTick::optimizer_due(const std::vector<bool>& supports) const {
  return !solved_ || supports != last_supports_ || ticks_ % optimizer_period_ticks == 0;
}

void WeightedTick::prepare(const Eigen::Ref<const Eigen::VectorXd>& q,
                           const Eigen::Ref<const Eigen::VectorXd>& v) {
  core_.compute(q, v, maps_);
  terms_.total_mass = maps_.total_mass;
}

bool WeightedTick::optimize(const Eigen::Ref<const Eigen::VectorXd>& q,
                            const Eigen::Ref<const Eigen::VectorXd>& v,
                            const std::vector<bool>& supports,
                            const Eigen::Ref<const RowMatrix>& wrenches,
                            const Eigen::Ref<const Eigen::VectorXd>& limit_errors,
                            const Eigen::Ref<const Eigen::VectorXd>& q_ref,
                            const Eigen::Ref<const Eigen::VectorXd>& v_ref,
                            const Eigen::Ref<const Eigen::VectorXd>& a_ref) {
  const bool found = optimizer_.optimize(terms_, core_.data(), q, v, supports, params, points,
                                         limit_errors, q_ref, v_ref, a_ref, wrenches, gravity_, x_);
  solved_ = true;
  last_supports_ = supports;
  return found;
}

std::string WeightedTick::check_finite() const {
  // controllers.base.check_finite_dynamics: NaN and ±inf propagate through one sum.
  double sum = terms_.bias_forces.sum() + terms_.r_bias.sum() + terms_.s_bias.sum() +
               terms_.linear_momentum.sum() + terms_.angular_momentum.sum();
  for (const ContactTerms& contact : terms_.contacts) {
    sum += contact.support_drift.sum() + contact.point_drift.sum();
  }
  if (std::isfinite(sum)) return "";
  std::vector<std::string> bad;
  if (!terms_.bias_forces.allFinite()) bad.emplace_back("bias forces");
  bool drifts = true;
  for (const ContactTerms& contact : terms_.contacts) {
    drifts = drifts && contact.support_drift.allFinite() && contact.point_drift.allFinite();
  }
  if (!drifts) bad.emplace_back("contact drifts");
  if (!(terms_.r_bias.allFinite() && terms_.s_bias.allFinite() &&
        terms_.linear_momentum.allFinite() && terms_.angular_momentum.allFinite())) {
    bad.emplace_back("momentum");
  }
  if (bad.empty()) return "";  // a finite overflow of the sum alone
  std::ostringstream message;
  message << "non-finite ";
  for (std::size_t i = 0; i < bad.size(); ++i) message << (i ? ", " : "") << bad[i];
  return message.str();
}

std::string WeightedTick::compute(const Eigen::Ref<const Eigen::VectorXd>& q,
                                  const Eigen::Ref<const Eigen::VectorXd>& v,
                                  const std::vector<bool>& supports,
                                  const Eigen::Ref<const RowMatrix>& measured_wrenches,
                                  const Eigen::Ref<const Eigen::VectorXd>& q_ref,
                                  const Eigen::Ref<const Eigen::VectorXd>& v_ref,
                                  const Eigen::Ref<const Eigen::VectorXd>& a_ref, bool prepared,
                                  bool want_diagnostics) {
  optimizer_ran_ = optimizer_due(supports);
  ++ticks_;
  if (!prepared) prepare(q, v);
  std::string failure = check_finite();
  if (!failure.empty()) return failure;
  if (optimizer_ran_) {
    // β_ba's p and g (eq. 5.17): the state's measured wrenches whenever sent, else the
    // previous command's (none on the first tick).
    const bool have_measured = measured_wrenches.rows() > 0;
    if (limits_) {
      limits_->errors(q, limit_errors_);
    } else {
      limit_errors_.setZero();
    }
    const bool fixed_pose = q_ref.size() == 0;
    if (fixed_pose) q_ref_ = params.reference_configuration;
    optimize(q, v, supports,
             have_measured ? measured_wrenches : Eigen::Ref<const RowMatrix>(last_wrenches_),
             limit_errors_,
             fixed_pose ? Eigen::Ref<const Eigen::VectorXd>(q_ref_) : q_ref,
             fixed_pose ? Eigen::Ref<const Eigen::VectorXd>(zero_) : v_ref,
             fixed_pose ? Eigen::Ref<const Eigen::VectorXd>(zero_) : a_ref);
  }
  const InverseDynamicsResult& result =
      measured_ground_forces
          ? inverse_dynamics_.solve_measured(terms_, x_, measured_wrenches)
          : inverse_dynamics_.solve(terms_, x_, supports, params.friction_coefficients, weights);
  if (result.status == InverseDynamicsStatus::mass_matrix_not_positive) {
    return std::string("a linear solve failed at this state: ") + result.detail;
  }
  if (result.status != InverseDynamicsStatus::ok) return result.detail;
  last_wrenches_ = result.contact_wrench_in_world;
  if (want_diagnostics) fill_diagnostics(supports);
  return "";
}

void WeightedTick::fill_diagnostics(const std::vector<bool>& supports) {
  const Eigen::VectorXd& acceleration = result().acceleration;
  diagnostics_.position_com_in_world = terms_.position_com_in_world;
  diagnostics_.linear_momentum = terms_.linear_momentum;
  diagnostics_.angular_momentum = terms_.angular_momentum;
  diagnostics_.linear_momentum_rate.noalias() = terms_.R * acceleration;
  diagnostics_.linear_momentum_rate += terms_.r_bias;
  diagnostics_.angular_momentum_rate.noalias() = terms_.S * acceleration;
  diagnostics_.angular_momentum_rate += terms_.s_bias;
  if (optimizer_ran_) {  // built for the optimizer this tick
    diagnostics_.support_polygon = optimizer_.last_support_polygon();
  } else {
    optimizer_.support_polygon(terms_, supports, diagnostics_.support_polygon);
  }
  optimizer_.residuals(acceleration, diagnostics_.objective_residuals);
  optimizer_.report_with_conditioning();
}

}  // namespace poise
