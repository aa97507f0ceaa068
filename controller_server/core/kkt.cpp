#include "kkt.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace poise {

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
}  // namespace

double damping_for_gain_bound(double sigma_min, double gain_bound) {
  if (sigma_min >= 1.0 / gain_bound) return 0.0;
  if (sigma_min >= 0.5 / gain_bound) {
    return std::sqrt(std::max(sigma_min / gain_bound - sigma_min * sigma_min, 0.0));
  }
  return 0.5 / gain_bound;
}

bool DampedCholesky::positive_definite_after_shift(const Eigen::Ref<const Eigen::MatrixXd>& gram,
                                                   double shift) {
  shifted_ = gram;
  shifted_.diagonal().array() -= shift;
  test_.compute(shifted_);
  return test_.info() == Eigen::Success;
}

bool DampedCholesky::compute(const Eigen::Ref<const Eigen::MatrixXd>& gram, double gain_bound) {
  const double inner_edge = 1.0 / (gain_bound * gain_bound);    // σ_min² = (1/B)²
  const double outer_edge = std::pow(0.5 / gain_bound, 2);       // σ_min² = (1/(2B))²
  if (positive_definite_after_shift(gram, outer_edge)) {         // σ_min > 1/(2B)
    if (positive_definite_after_shift(gram, inner_edge)) {       // σ_min > 1/B: undamped
      damping_ = 0.0;
    } else {  // 1/(2B) < σ_min ≤ 1/B: λ depends on σ_min
      eigen_.compute(gram, Eigen::EigenvaluesOnly);
      const double sigma_min = std::sqrt(std::max(eigen_.eigenvalues()(0), 0.0));
      damping_ = damping_for_gain_bound(sigma_min, gain_bound);
    }
  } else {  // σ_min ≤ 1/(2B)
    damping_ = 0.5 / gain_bound;
  }
  shifted_ = gram;
  if (damping_ != 0.0) shifted_.diagonal().array() += damping_ * damping_;
  factor_.compute(shifted_);
  if (factor_.info() != Eigen::Success) return false;
  return factor_.matrixLLT().allFinite();
}

double DampedCholesky::damped_condition() const {
  const double reciprocal = factor_.rcond();
  return reciprocal > 0 ? std::max(1.0 / reciprocal, 1.0) : kInf;
}

bool WeightedKKT::solve(const Eigen::Ref<const Eigen::MatrixXd>& hessian,
                        const Eigen::Ref<const Eigen::VectorXd>& gradient,
                        const Eigen::Ref<const Eigen::MatrixXd>& C,
                        const Eigen::Ref<const Eigen::VectorXd>& d, double objective_gain_bound,
                        double constraint_gain_bound, Eigen::Ref<Eigen::VectorXd> x,
                        KKTResult& result) {
  result = KKTResult{};
  schur_factored_ = false;
  if (!objective_.compute(hessian, objective_gain_bound)) {
    x.setZero();
    result.objective_damping = kNaN;
    result.constraint_residual = kInf;
    result.objective_condition_number = kInf;
    result.schur_condition_number = kInf;
    result.conditioning_estimated = true;
    return false;
  }
  x_free_ = gradient;
  objective_.solve_in_place(x_free_);
  result.objective_damping = objective_.damping();
  if (C.rows() == 0) {
    x = x_free_;
    result.schur_condition_number = 1.0;
  } else {
    M_inv_CT_ = C.transpose();
    objective_.solve_in_place(M_inv_CT_);
    schur_.noalias() = C * M_inv_CT_;
    rhs_.noalias() = d - C * x_free_;
    if (schur_factor_.compute(schur_, constraint_gain_bound)) {
      multipliers_ = rhs_;
      schur_factor_.solve_in_place(multipliers_);
      result.constraint_damping = schur_factor_.damping();
      schur_factored_ = true;
    } else {  // damped_solve_psd: by eigenvalues
      eigen_.compute(0.5 * (schur_ + schur_.transpose()));
      Eigen::VectorXd values = eigen_.eigenvalues().cwiseMax(0.0);
      const double sigma_min = std::sqrt(values(0));
      const double damping = damping_for_gain_bound(sigma_min, constraint_gain_bound);
      result.constraint_damping = damping;
      result.schur_condition_number =
          values(0) > 0 ? values(values.size() - 1) / values(0) : kInf;
      Eigen::VectorXd denominator = values.array() + damping * damping;
      for (Eigen::Index i = 0; i < denominator.size(); ++i) {
        if (denominator(i) <= 0.0) denominator(i) = kInf;
      }
      multipliers_.noalias() = eigen_.eigenvectors().transpose() * rhs_;
      multipliers_.array() /= denominator.array();
      multipliers_ = eigen_.eigenvectors() * multipliers_;
    }
    x = x_free_;
    x.noalias() += M_inv_CT_ * multipliers_;
  }
  result.found = x.allFinite();
  if (!result.found) {
    x.setZero();
    result.constraint_residual = kInf;
  } else {
    if (C.rows()) {
      rhs_.noalias() = C * x;
      rhs_ -= d;
      result.constraint_residual = rhs_.norm();
    } else {
      result.constraint_residual = 0.0;
    }
  }
  return result.found;
}

void WeightedKKT::estimate_conditioning(KKTResult& result) const {
  if (result.conditioning_estimated) return;
  result.conditioning_estimated = true;
  result.objective_condition_number = objective_.damped_condition();
  if (!schur_factored_) return;  // no constraint (1), or by eigenvalues in solve()
  if (result.constraint_damping > 0) {  // the undamped Schur complement's conditioning
    eigen_.compute(schur_, Eigen::EigenvaluesOnly);
    const Eigen::VectorXd& values = eigen_.eigenvalues();
    result.schur_condition_number = values(0) > 0 ? values(values.size() - 1) / values(0) : kInf;
  } else {
    result.schur_condition_number = schur_factor_.damped_condition();
  }
}

}  // namespace poise
