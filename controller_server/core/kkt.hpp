// Closed-form KKT solve of Macchietto 2008, App. D, with damped least squares
// (Maciejewski 1990, eq. 15–18): controller_server/solvers/kkt.py and math/damped.py.
//
//   min_x ½ ‖W (b − A x)‖²  s.t.  C x = d                        (D.1)
//   M = Aᵀ Wᵀ W A,  u = Aᵀ Wᵀ W b
//   C M⁻¹ Cᵀ λ = d − C M⁻¹ u                                      (D.7)
//   M x = u + Cᵀ λ                                                (D.8)
//
// Both solves are damped with λ chosen from the smallest singular value so that a gain
// bound B holds (damping_for_gain_bound); the bands of σ_min are found by Cholesky
// factorizations of shifted matrices, as damped_cholesky does. Workspaces are sized once
// per (n, constraint rows): no allocation per tick once both have been seen.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>

namespace poise {

// damped.damping_for_gain_bound: the smallest λ with σ/(σ² + λ²) ≤ B for all σ ≥ σ_min.
double damping_for_gain_bound(double sigma_min, double gain_bound);

// A damped Cholesky factor of a Gram matrix G: L Lᵀ = G + λ² I (damped.damped_cholesky).
class DampedCholesky {
 public:
  // Factors `gram` (lower triangle read); false if G + λ² I is not finite positive definite.
  bool compute(const Eigen::Ref<const Eigen::MatrixXd>& gram, double gain_bound);
  double damping() const { return damping_; }
  // (G + λ² I)⁻¹ rhs, in place.
  template <typename Derived>
  void solve_in_place(Eigen::MatrixBase<Derived>& rhs) const {
    factor_.solveInPlace(rhs);
  }
  // Condition number of G + λ² I (1-norm estimate, as LAPACK's dpocon); diagnostics only.
  double damped_condition() const;

 private:
  bool positive_definite_after_shift(const Eigen::Ref<const Eigen::MatrixXd>& gram, double shift);
  Eigen::MatrixXd shifted_;
  Eigen::LLT<Eigen::MatrixXd> test_;
  Eigen::LLT<Eigen::MatrixXd> factor_;
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen_;
  double damping_ = 0.0;
};

struct KKTResult {
  bool found = false;
  double objective_damping = 0.0;
  double constraint_damping = 0.0;
  double constraint_residual = 0.0;
  // Condition numbers (diagnostics, by WeightedKKT::estimate_conditioning): of the damped
  // M, and of C M⁻¹ Cᵀ before damping.
  double objective_condition_number = 0.0;
  double schur_condition_number = 1.0;
  bool conditioning_estimated = false;
};

// solve_weighted_kkt on the normal equations (M, u) and the equality (C, d).
class WeightedKKT {
 public:
  // x (size n) is written; false (x = 0) if no finite solution. The condition numbers are
  // left for estimate_conditioning (diagnostics only: they cost as much as a factor).
  bool solve(const Eigen::Ref<const Eigen::MatrixXd>& hessian,
             const Eigen::Ref<const Eigen::VectorXd>& gradient,
             const Eigen::Ref<const Eigen::MatrixXd>& C, const Eigen::Ref<const Eigen::VectorXd>& d,
             double objective_gain_bound, double constraint_gain_bound,
             Eigen::Ref<Eigen::VectorXd> x, KKTResult& result);

  // The condition numbers of the last solve into `result` (KKTSolution's properties,
  // estimated on demand as there): of the damped M, and of C M⁻¹ Cᵀ before damping.
  void estimate_conditioning(KKTResult& result) const;

 private:
  bool schur_factored_ = false;  // the last solve factored C M⁻¹ Cᵀ (else: none, or eigen)
  DampedCholesky objective_, schur_factor_;
  Eigen::MatrixXd M_inv_CT_, schur_;
  Eigen::VectorXd x_free_, rhs_, multipliers_;
  mutable Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen_;
};

}  // namespace poise
