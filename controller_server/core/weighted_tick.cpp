#include "weighted_tick.hpp"

namespace poise {

namespace {
std::vector<Eigen::Index> point_counts(const DynamicsCore& core) {
  std::vector<Eigen::Index> counts;
  for (const ContactSpec& contact : core.contacts()) counts.push_back(contact.points_in_frame.rows());
  return counts;
}
}  // namespace

WeightedTick::WeightedTick(const DynamicsCore& core, std::size_t)
    : core_(core.clone()),
      terms_(core.model().nv, point_counts(core)),
      maps_(terms_.maps()),
      optimizer_(core_.model(), core.contacts().size()),
      x_(Eigen::VectorXd::Zero(core.model().nv)),
      gravity_(core.model().gravity.linear().norm()) {
  params.joint_weights = Eigen::VectorXd::Ones(core.model().nv - 6);
  params.friction_coefficients = Eigen::VectorXd::Ones(static_cast<Eigen::Index>(core.contacts().size()));
}

void WeightedTick::reset() {
  solved_ = false;
  ticks_ = 0;
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

}  // namespace poise
