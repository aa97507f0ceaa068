// Floating-base inverse dynamics with contact forces in friction pyramids, in C++:
// controller_server.inverse_dynamics.solve_inverse_dynamics, its executable
// specification, step for step (Macchietto 2008, eq. 4.2, with S = [0 I]):
//
//     M q̈ + h = Sᵀ τ + J_cᵀ f
//
// Measured mode: τ compensates the client's ground wrenches. Distributed mode: the
// exact case first (minimum_norm_balance: f = Gᵀ (G Gᵀ)⁻¹ w, no solver), then the
// nearest feasible motion (_condensed_motion's QP in the forces, the full QP in
// [q̈, f] when its torques exceed their limits), then _least_squares_balance when no
// solver answers; every path but the exact one ends in _realize (clipped τ, the q̈
// they produce). The QPs are eiquadprog's EiquadprogFast (Goldfarb–Idnani's dual active-set
// method, as the Python path's quadprog) with the Python path's data scaling (_solve_qp,
// QP_DATA_SCALE): exactly feasible to rounding, so the two kernels agree to rounding.
//
// Allocation: everything a solve touches is allocated at construction or on the
// first solve with a new combination of support flags (one SupportSet per
// combination, holding that combination's matrices and its two QP solvers, each sized once);
// later solves with those flags allocate nothing.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "dynamics_core.hpp"
#include "terms.hpp"

namespace poise {

// Which branch of solve_inverse_dynamics produced the result.
enum class InverseDynamicsPath {
  measured,       // measured ground wrenches, τ clipped (_realize)
  exact,          // minimum-norm forces in the cones, τ within limits: q̈ as requested
  condensed_qp,   // nearest_feasible_motion by _condensed_motion's QP in f
  full_qp,        // nearest_feasible_motion by the full QP in [q̈, f]
  least_squares,  // no QP answer: _least_squares_balance's forces, q̈ as requested, clipped τ
};

const char* path_name(InverseDynamicsPath path);

enum class InverseDynamicsStatus {
  ok,
  non_finite_input,         // an input is NaN or infinite: nothing was solved
  mass_matrix_not_positive  // M's Cholesky failed (Python: np.linalg.LinAlgError)
};

// Field names of InverseDynamicsResult (inverse_dynamics.py); overwritten by every solve.
struct InverseDynamicsResult {
  Eigen::VectorXd joint_torque;         // (nv − 6,): actuated torques within limits (N·m, N)
  Points contact_force_in_world;        // (points, 3): zero off the supports and when measured (N)
  RowMatrix contact_wrench_in_world;    // (contacts, 6): force and torque about each contact
                                        // frame origin, world axes (N, N·m)
  Eigen::VectorXd acceleration;         // (nv,): the q̈ that τ and f produce
  double root_wrench_residual = 0.0;    // ‖(M q̈ + h − J_cᵀ f)_root‖ before correction (N, N·m)
  int saturated_joints = 0;             // DoFs whose torque was clipped
  InverseDynamicsPath path = InverseDynamicsPath::exact;
  int qp_iterations = 0;    // active-set iterations over this solve's QPs
  int qp_failures = 0;      // QP solves of this call that gave no answer (not optimal)
  InverseDynamicsStatus status = InverseDynamicsStatus::ok;
  const char* detail = "";  // with a status other than ok: what was wrong (a static string)
};

// Weights of nearest_feasible_motion, as solve_inverse_dynamics' keyword arguments.
struct InverseDynamicsWeights {
  double force_regularization = 1e-4;  // ε on ‖f‖² when q̈ cannot be realized
  double support_weight = 100.0;       // w_s per kg of robot mass on the supports' acceleration
};

struct SupportSet;  // one combination of support flags: its matrices and QPs (the .cpp)

// One session's inverse dynamics: sizes and torque limits fixed at construction.
// One object per session: solve() may run without the GIL, but never twice at once on the
// same object (callers that share one lock mutex(), as the Python binding does).
class InverseDynamics {
 public:
  // nv DoFs (the first 6 the free-flyer root), contacts with point_counts[c] sole points
  // each, torque_limit (nv − 6,) symmetric limits (finite, ≥ 0). Throws
  // std::invalid_argument on inconsistent sizes or bad limits.
  InverseDynamics(Eigen::Index nv, std::vector<Eigen::Index> point_counts,
                  Eigen::VectorXd torque_limit);
  ~InverseDynamics();
  InverseDynamics(InverseDynamics&&) noexcept;
  InverseDynamics& operator=(InverseDynamics&&) noexcept;

  // Distributed mode: forces on the supporting contacts (one flag per contact), μ per
  // contact. Throws std::invalid_argument on sizes that do not match the construction.
  const InverseDynamicsResult& solve(const Terms& terms,
                                     const Eigen::Ref<const Eigen::VectorXd>& acceleration,
                                     const std::vector<bool>& supports,
                                     const Eigen::Ref<const Eigen::VectorXd>& friction_coefficients,
                                     const InverseDynamicsWeights& weights = {});

  // Measured mode: measured_wrenches_in_world (contacts, 6) ground wrenches [f; m about the
  // contact frame origin], world axes.
  const InverseDynamicsResult& solve_measured(
      const Terms& terms, const Eigen::Ref<const Eigen::VectorXd>& acceleration,
      const Eigen::Ref<const RowMatrix>& measured_wrenches_in_world);

  const InverseDynamicsResult& result() const { return result_; }
  Eigen::Index nv() const { return nv_; }
  const std::vector<Eigen::Index>& point_counts() const { return point_counts_; }
  const Eigen::VectorXd& torque_limit() const { return torque_limit_; }
  // Support-flag combinations seen so far, and the QP solvers they hold: both grow
  // only with a new combination (or its first QP), never with a repeated one.
  std::size_t support_set_count() const { return support_sets_.size(); }
  std::size_t qp_cache_size() const;
  // Heap allocations made by this object after construction (support sets, QPs).
  std::size_t workspace_allocations() const { return workspace_allocations_; }
  std::mutex& mutex() const { return *mutex_; }

 private:
  SupportSet& support_set(const std::vector<bool>& supports);
  void check_sizes(const Terms& terms, const char* caller) const;
  // A new solve: the result's status and counters cleared, then false (status
  // non_finite_input) if the terms or the acceleration are not finite.
  bool start_solve(const Terms& terms, const Eigen::Ref<const Eigen::VectorXd>& acceleration);
  bool minimum_norm_balance(SupportSet& set, const Eigen::Matrix<double, 6, 1>& wrench);
  bool condensed_motion(SupportSet& set, const Terms& terms,
                        const Eigen::Ref<const Eigen::VectorXd>& acceleration,
                        const InverseDynamicsWeights& weights, double support_weight);
  bool full_motion(SupportSet& set, const Terms& terms,
                   const Eigen::Ref<const Eigen::VectorXd>& acceleration,
                   const InverseDynamicsWeights& weights, double support_weight);
  void least_squares_balance(SupportSet& set, const Eigen::Matrix<double, 6, 1>& wrench,
                             double regularization);
  void place_forces(const SupportSet& set, const std::vector<bool>& supports, const Terms& terms);
  void realize(const Terms& terms, const Eigen::Ref<const Eigen::VectorXd>& acceleration);

  Eigen::Index nv_;
  std::vector<Eigen::Index> point_counts_;
  std::vector<Eigen::Index> point_starts_;  // first point of each contact
  Eigen::VectorXd torque_limit_;
  std::vector<std::unique_ptr<SupportSet>> support_sets_;
  std::size_t workspace_allocations_ = 0;

  // Workspace of every support combination (sizes nv and the number of points).
  Eigen::VectorXd generalized_force_;          // M q̈ + h, (nv,)
  Eigen::VectorXd contact_generalized_force_;  // J_cᵀ f, (nv,)
  Eigen::VectorXd torque_;                     // (nv − 6,)
  Eigen::VectorXd applied_;                    // Sᵀ τ + J_cᵀ f − h, (nv,)
  Eigen::VectorXd motion_;                     // the target q̈ of _realize, (nv,)
  Eigen::LLT<Eigen::MatrixXd> mass_llt_;       // M = L Lᵀ
  Eigen::MatrixXd condensed_hessian_;          // N = M + w_s J_supᵀ J_sup, (nv, nv)
  Eigen::LLT<Eigen::MatrixXd> condensed_llt_;  // N = L Lᵀ
  Eigen::Matrix<double, Eigen::Dynamic, 7> condensed_rhs_;  // N⁻¹ [M_rootᵀ, −g]: [Y, Δ₀]
  Eigen::LLT<Eigen::Matrix<double, 6, 6>> root_llt_;        // G Gᵀ, then K
  InverseDynamicsResult result_;
  std::unique_ptr<std::mutex> mutex_ = std::make_unique<std::mutex>();
};

}  // namespace poise
