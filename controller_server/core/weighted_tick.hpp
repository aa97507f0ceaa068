// One tick of the weighted controllers (momentum, tracking) in one call: the dynamics
// terms (DynamicsCore), the optimizer every N-th tick or when the supports change
// (WeightedOptimizer: Macchietto 2008, eq. 5.1), then the inverse dynamics of eq. 4.2 on
// the latest q̈ (InverseDynamics). The state between ticks (the last q̈, its supports, the
// commanded wrenches that eq. 5.17's COP and CMP fall back on) is MomentumController's
// (controllers/momentum.py), which stays the specification.
//
// Between optimizer runs the Python realizes the last q̈ by two RNEA passes when it can
// (exact_inverse_dynamics); here the terms are computed every tick (16–24 µs) and the same
// minimum-norm forces come from solve(): equal to rounding.
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "dynamics_core.hpp"
#include "inverse_dynamics.hpp"
#include "joint_limits.hpp"
#include "terms.hpp"
#include "weighted.hpp"

namespace poise {

// What the diagnostics read at a tick (MomentumController._diagnostics), when wanted.
struct TickDiagnostics {
  Eigen::Vector3d position_com_in_world, linear_momentum, angular_momentum;
  Eigen::Vector3d linear_momentum_rate, angular_momentum_rate;  // of the commanded q̈
  Polygon support_polygon;
  std::vector<std::pair<std::string, double>> objective_residuals;
};

class WeightedTick {
 public:
  WeightedTick(const DynamicsCore& core, Eigen::VectorXd torque_limit);

  WeightedParams params;
  std::vector<PointTarget> points;
  int optimizer_period_ticks = 1;
  bool measured_ground_forces = false;  // ground_force_mode "measured"
  InverseDynamicsWeights weights;       // force_regularization, support_weight

  // Whether the next tick with these supports runs the optimizer (MomentumController).
  bool optimizer_due(const std::vector<bool>& supports) const;

  // The dynamics terms at (q, v) into terms(); data() then holds the state's kinematics.
  // A behaviour observes them before compute(…, prepared = true) finishes the tick.
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

  // The soft joint limits of eq. 6.5–6.6 (none until set: no gain is raised).
  void set_limits(JointLimits limits);

  // A whole tick: terms (unless `prepared`), the optimizer when due, the inverse dynamics.
  // `measured_wrenches`: the state's ground wrenches (contacts, 6) or 0 rows. Empty
  // references (size 0) select the fixed pose of params. Returns "" or why there is no
  // command (non-finite dynamics: the message MomentumController raises).
  std::string compute(const Eigen::Ref<const Eigen::VectorXd>& q,
                      const Eigen::Ref<const Eigen::VectorXd>& v,
                      const std::vector<bool>& supports,
                      const Eigen::Ref<const RowMatrix>& measured_wrenches,
                      const Eigen::Ref<const Eigen::VectorXd>& q_ref,
                      const Eigen::Ref<const Eigen::VectorXd>& v_ref,
                      const Eigen::Ref<const Eigen::VectorXd>& a_ref, bool prepared,
                      bool want_diagnostics);

  const Terms& terms() const { return terms_; }
  const DynamicsCore& core() const { return core_; }
  const Data& data() const { return core_.data(); }
  const Model& model() const { return core_.model(); }
  const Eigen::VectorXd& acceleration_desired() const { return x_; }
  WeightedOptimizer& optimizer() { return optimizer_; }
  const InverseDynamicsResult& result() const { return inverse_dynamics_.result(); }
  const TickDiagnostics& diagnostics() const { return diagnostics_; }
  bool optimizer_ran() const { return optimizer_ran_; }

 private:
  std::string check_finite() const;
  void fill_diagnostics(const std::vector<bool>& supports);

  DynamicsCore core_;
  Terms terms_;
  TermsOut maps_;
  WeightedOptimizer optimizer_;
  InverseDynamics inverse_dynamics_;
  std::optional<JointLimits> limits_;
  Eigen::VectorXd limit_errors_;  // e per DoF (eq. 6.5–6.6)
  Eigen::VectorXd x_;
  Eigen::VectorXd q_ref_, zero_;  // the fixed pose's reference, and v_ref = a_ref = 0
  RowMatrix last_wrenches_;       // the last command's ground wrenches (rows 0: none yet)
  bool solved_ = false;
  bool optimizer_ran_ = false;
  std::vector<bool> last_supports_;
  long ticks_ = 0;
  double gravity_;
  TickDiagnostics diagnostics_;
};

}  // namespace poise
