// One tick of the weighted controllers (momentum, tracking) in one call: the dynamics
// terms (DynamicsCore), the optimizer every N-th tick or when the supports change
// (WeightedOptimizer: Macchietto 2008, eq. 5.1), then the inverse dynamics of eq. 4.2 on
// the latest q̈. The state between ticks (the last q̈, supports, commanded wrenches) is
// MomentumController's (controllers/momentum.py), which stays the specification.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "dynamics_core.hpp"
#include "terms.hpp"
#include "weighted.hpp"

namespace poise {

class WeightedTick {
 public:
  WeightedTick(const DynamicsCore& core, std::size_t point_counts_hint = 0);

  WeightedParams params;
  std::vector<PointTarget> points;
  int optimizer_period_ticks = 1;

  // Forget the last solution (the next tick runs the optimizer).
  void reset();
  // Whether the next tick with these supports runs the optimizer (MomentumController).
  bool optimizer_due(const std::vector<bool>& supports) const;

  // The dynamics terms at (q, v) into terms(); data() then holds the state's kinematics.
  void prepare(const Eigen::Ref<const Eigen::VectorXd>& q,
               const Eigen::Ref<const Eigen::VectorXd>& v);
  // The optimizer at the prepared state; false if the KKT found no finite q̈.
  bool optimize(const Eigen::Ref<const Eigen::VectorXd>& q,
                const Eigen::Ref<const Eigen::VectorXd>& v, const std::vector<bool>& supports,
                const Eigen::Ref<const RowMatrix>& wrenches,
                const Eigen::Ref<const Eigen::VectorXd>& limit_errors,
                const Eigen::Ref<const Eigen::VectorXd>& q_ref,
                const Eigen::Ref<const Eigen::VectorXd>& v_ref,
                const Eigen::Ref<const Eigen::VectorXd>& a_ref);

  const Terms& terms() const { return terms_; }
  const Data& data() const { return core_.data(); }
  const Model& model() const { return core_.model(); }
  const Eigen::VectorXd& acceleration_desired() const { return x_; }
  WeightedOptimizer& optimizer() { return optimizer_; }
  double gravity() const { return gravity_; }

 private:
  DynamicsCore core_;
  Terms terms_;
  TermsOut maps_;
  WeightedOptimizer optimizer_;
  Eigen::VectorXd x_;
  bool solved_ = false;
  std::vector<bool> last_supports_;
  long ticks_ = 0;
  double gravity_;
};

}  // namespace poise
