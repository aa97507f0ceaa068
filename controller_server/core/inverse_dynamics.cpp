// solve_inverse_dynamics of controller_server/inverse_dynamics.py in C++ (see the header).
// Each function below names the Python function it mirrors; the order of operations is
// the Python's, so that the exact and measured cases agree to rounding.
#include "inverse_dynamics.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#include <eiquadprog/eiquadprog-fast.hpp>

namespace poise {

namespace {

constexpr Eigen::Index kRootDofs = 6;  // NUM_ROOT_DOFS: the free flyer's unactuated rows
// QP_DATA_SCALE: linear QP data larger than this are solved scaled down to it (_solve_qp).
constexpr double kQpDataScale = 1e6;
// Torque differences below this are solver tolerance, not saturation (_realize).
constexpr double kSaturationTolerance = 1e-6;

using Vector6 = Eigen::Matrix<double, 6, 1>;
using RootRows = Eigen::Matrix<double, 6, Eigen::Dynamic>;
using eiquadprog::solvers::EiquadprogFast;

}  // namespace

// One QP of fixed sizes, by eiquadprog's Goldfarb–Idnani dual active-set method (Python:
// quadprog through qpsolvers, the same method): the solver, sized once by reset(), and its
// data in the column-major layout and sign convention it reads,
//   min ½ xᵀ H x + gᵀ x  s.t.  CE x + ce0 = 0,  CI x + ci0 ≥ 0
// (ours: G x ≤ h is CI = −G, ci0 = h; A x = b is CE = A, ce0 = −b).
struct QpWorkspace {
  EiquadprogFast solver;
  Eigen::MatrixXd hessian, ce, ci;
  Eigen::VectorXd gradient, ce0, ci0, x;

  QpWorkspace(Eigen::Index n, Eigen::Index n_eq, Eigen::Index n_in)
      : hessian(Eigen::MatrixXd::Zero(n, n)), ce(Eigen::MatrixXd::Zero(n_eq, n)),
        ci(Eigen::MatrixXd::Zero(n_in, n)), gradient(Eigen::VectorXd::Zero(n)),
        ce0(Eigen::VectorXd::Zero(n_eq)), ci0(Eigen::VectorXd::Zero(n_in)),
        x(Eigen::VectorXd::Zero(n)) {
    solver.reset(static_cast<std::size_t>(n), static_cast<std::size_t>(n_eq),
                 static_cast<std::size_t>(n_in));
  }
};

namespace {

// friction_pyramid's rows for one point, written into `cones` at (5i, 3i): ±f_x − μ' f_z ≤ 0,
// ±f_y − μ' f_z ≤ 0, −f_z ≤ 0 with μ' = μ/√2 (the pyramid inscribed in Coulomb's cone).
template <typename Matrix>
void write_pyramid(Matrix& cones, Eigen::Index point, double mu_circular) {
  const double mu = mu_circular / std::sqrt(2.0);
  auto block = cones.block(5 * point, 3 * point, 5, 3);
  block << 1, 0, -mu, -1, 0, -mu, 0, 1, -mu, 0, -1, -mu, 0, 0, -1;
}

}  // namespace

const char* path_name(InverseDynamicsPath path) {
  switch (path) {
    case InverseDynamicsPath::measured: return "measured";
    case InverseDynamicsPath::exact: return "exact";
    case InverseDynamicsPath::condensed_qp: return "condensed_qp";
    case InverseDynamicsPath::full_qp: return "full_qp";
    case InverseDynamicsPath::least_squares: return "least_squares";
  }
  return "unknown";
}

// One combination of support flags: the supporting contacts' rows, and the workspaces
// and QP solvers of the QPs over their p points (created on the first QP).
struct SupportSet {
  std::vector<bool> supports;
  Eigen::Index contacts = 0;  // s supporting contacts
  Eigen::Index points = 0;    // p supporting points
  RowMatrix point_jacobian;   // (3p, nv): _support_points
  Eigen::VectorXd mus;        // (p,): μ per supporting point
  RowMatrix support_jacobian; // (6s, nv): J_sup
  Eigen::VectorXd support_drift;  // (6s,): J̇_sup q̇
  Eigen::VectorXd support_acceleration;  // (6s,): J_sup q̈_des + J̇_sup q̇
  Eigen::VectorXd point_force;    // (3p,): the answer, f in world axes (N)

  // minimum_norm_balance and the condensed QP (3p unknowns, 5p rows, no equality).
  Eigen::Matrix<double, 6, 6> balance;      // G Gᵀ
  Vector6 multipliers;                      // (G Gᵀ)⁻¹ w
  RootRows k_inv_a;                         // K⁻¹ A, (6, 3p)
  RowMatrix force_hessian;                  // (3p, 3p)
  Eigen::VectorXd force_gradient;           // (3p,)
  RowMatrix cones;                          // (5p, 3p): friction_pyramid
  Eigen::VectorXd cone_upper;               // 0
  std::unique_ptr<QpWorkspace> force_qp;    // _condensed_motion's and _least_squares_balance's

  // The full QP of nearest_feasible_motion (nv + 3p unknowns, 6 equalities).
  RowMatrix full_hessian;        // (nv + 3p, nv + 3p)
  Eigen::VectorXd full_gradient;
  RowMatrix full_inequality;     // (5p + 2(nv − 6), nv + 3p)
  Eigen::VectorXd full_upper;
  RowMatrix full_equality;       // (6, nv + 3p): the root rows of [M, −J_cᵀ]
  Eigen::VectorXd full_equality_rhs;  // −h_root
  Eigen::VectorXd full_solution;      // [q̈; f]
  std::unique_ptr<QpWorkspace> full_qp;

  SupportSet(std::vector<bool> flags, Eigen::Index nv, const std::vector<Eigen::Index>& counts)
      : supports(std::move(flags)) {
    for (std::size_t c = 0; c < counts.size(); ++c) {
      if (!supports[c]) continue;
      ++contacts;
      points += counts[c];
    }
    const Eigen::Index p = points, n = nv + 3 * points;
    const Eigen::Index n_in = 5 * p + 2 * (nv - kRootDofs);
    point_jacobian = RowMatrix::Zero(3 * p, nv);
    mus = Eigen::VectorXd::Zero(p);
    support_jacobian = RowMatrix::Zero(6 * contacts, nv);
    support_drift = Eigen::VectorXd::Zero(6 * contacts);
    support_acceleration = Eigen::VectorXd::Zero(6 * contacts);
    point_force = Eigen::VectorXd::Zero(3 * p);
    k_inv_a = RootRows::Zero(6, 3 * p);
    force_hessian = RowMatrix::Zero(3 * p, 3 * p);
    force_gradient = Eigen::VectorXd::Zero(3 * p);
    cones = RowMatrix::Zero(5 * p, 3 * p);
    cone_upper = Eigen::VectorXd::Zero(5 * p);
    full_hessian = RowMatrix::Zero(n, n);
    full_gradient = Eigen::VectorXd::Zero(n);
    full_inequality = RowMatrix::Zero(n_in, n);
    full_upper = Eigen::VectorXd::Zero(n_in);
    full_equality = RowMatrix::Zero(kRootDofs, n);
    full_equality_rhs = Eigen::VectorXd::Zero(kRootDofs);
    full_solution = Eigen::VectorXd::Zero(n);
  }
};

namespace {

// _solve_qp: min ½ xᵀ P x + qᵀ x s.t. G x ≤ h, A x = b. A finite x (written to `x`), or
// false. Linear data larger than QP_DATA_SCALE are divided by k to that size (in place: the
// callers rebuild them every solve) and x = k y is returned. Non-finite data are not handed
// to the solver. The QP's workspace is made on its first solve, sized once (reset); later
// solves copy into it and allocate nothing.
bool solve_qp(std::unique_ptr<QpWorkspace>& qp, std::size_t& allocations,
              InverseDynamicsResult& stats, const RowMatrix& P, Eigen::VectorXd& q,
              const RowMatrix& G, Eigen::VectorXd& h, const RowMatrix* A, Eigen::VectorXd* b,
              Eigen::Ref<Eigen::VectorXd> x) {
  double scale = 0.0;  // max |[q; h; b]|
  const Eigen::VectorXd* const linear_data[] = {&q, &h, b};
  for (const Eigen::VectorXd* linear : linear_data) {
    if (linear == nullptr) continue;
    if (!linear->allFinite()) return false;
    scale = std::max(scale, linear->lpNorm<Eigen::Infinity>());
  }
  if (!P.allFinite() || !G.allFinite()) return false;
  if (A != nullptr && !A->allFinite()) return false;
  const double k = std::max(1.0, scale / kQpDataScale);
  if (k > 1.0) {
    q /= k;
    h /= k;
    if (b != nullptr) *b /= k;
  }
  if (q.size() == 0) {
    // solve_qp_bounded's _solve_empty: no unknowns, found if 0 ≤ h and b = 0.
    const bool found = (h.array() >= 0.0).all() && (b == nullptr || (b->array() == 0.0).all());
    return found;
  }
  if (!qp) {
    qp = std::make_unique<QpWorkspace>(q.size(), A == nullptr ? 0 : A->rows(), G.rows());
    ++allocations;
  }
  qp->hessian = P;
  qp->gradient = q;
  qp->ci = -G;
  qp->ci0 = h;
  if (A != nullptr) {
    qp->ce = *A;
    qp->ce0 = -*b;
  }
  const auto status = qp->solver.solve_quadprog(qp->hessian, qp->gradient, qp->ce, qp->ce0,
                                                qp->ci, qp->ci0, qp->x);
  stats.qp_iterations += qp->solver.getIteratios();
  if (status != eiquadprog::solvers::EIQUADPROG_FAST_OPTIMAL) {
    ++stats.qp_failures;  // infeasible (by rounding: every QP here is feasible) or at max_iter
    return false;
  }
  x = qp->x;
  if (k > 1.0) x *= k;
  return x.allFinite();
}

}  // namespace

InverseDynamics::InverseDynamics(Eigen::Index nv, std::vector<Eigen::Index> point_counts,
                                 Eigen::VectorXd torque_limit)
    : nv_(nv), point_counts_(std::move(point_counts)), torque_limit_(std::move(torque_limit)) {
  if (nv_ <= kRootDofs) {
    throw std::invalid_argument("nv=" + std::to_string(nv_) +
                                ": a floating base has 6 root DoFs and at least one joint");
  }
  if (torque_limit_.size() != nv_ - kRootDofs) {
    throw std::invalid_argument("torque_limit has " + std::to_string(torque_limit_.size()) +
                                " entries, expected nv - 6 = " + std::to_string(nv_ - kRootDofs));
  }
  // +inf: a joint without a limit (a model file that gives none), as the Python takes it.
  if (!(torque_limit_.array() >= 0.0).all()) {
    throw std::invalid_argument("torque_limit must be >= 0 (+inf for none), not NaN");
  }
  Eigen::Index points = 0;
  for (Eigen::Index count : point_counts_) {
    if (count < 0) throw std::invalid_argument("point_counts must be >= 0");
    point_starts_.push_back(points);
    points += count;
  }
  generalized_force_ = Eigen::VectorXd::Zero(nv_);
  contact_generalized_force_ = Eigen::VectorXd::Zero(nv_);
  torque_ = Eigen::VectorXd::Zero(nv_ - kRootDofs);
  applied_ = Eigen::VectorXd::Zero(nv_);
  motion_ = Eigen::VectorXd::Zero(nv_);
  mass_llt_ = Eigen::LLT<Eigen::MatrixXd>(nv_);
  condensed_hessian_ = Eigen::MatrixXd::Zero(nv_, nv_);
  condensed_llt_ = Eigen::LLT<Eigen::MatrixXd>(nv_);
  condensed_rhs_ = Eigen::Matrix<double, Eigen::Dynamic, 7>::Zero(nv_, 7);
  result_.joint_torque = Eigen::VectorXd::Zero(nv_ - kRootDofs);
  result_.contact_force_in_world = Points::Zero(points, 3);
  result_.contact_wrench_in_world =
      RowMatrix::Zero(static_cast<Eigen::Index>(point_counts_.size()), 6);
  result_.acceleration = Eigen::VectorXd::Zero(nv_);
  // 2^contacts combinations at most, each created once.
  support_sets_.reserve(std::size_t{1} << std::min<std::size_t>(point_counts_.size(), 6));
}

InverseDynamics::~InverseDynamics() = default;
InverseDynamics::InverseDynamics(InverseDynamics&&) noexcept = default;
InverseDynamics& InverseDynamics::operator=(InverseDynamics&&) noexcept = default;

std::size_t InverseDynamics::qp_cache_size() const {
  std::size_t count = 0;
  for (const auto& set : support_sets_) count += (set->force_qp != nullptr) + (set->full_qp != nullptr);
  return count;
}

SupportSet& InverseDynamics::support_set(const std::vector<bool>& supports) {
  for (auto& set : support_sets_) {
    if (set->supports == supports) return *set;
  }
  support_sets_.push_back(std::make_unique<SupportSet>(supports, nv_, point_counts_));
  ++workspace_allocations_;
  return *support_sets_.back();
}

// Every matrix of `terms` that a solve reads has the size of this object's nv and points
// (terms_from_python copies whatever sizes Python had).
void InverseDynamics::check_sizes(const Terms& terms, const char* caller) const {
  bool ok = terms.mass_matrix.rows() == nv_ && terms.mass_matrix.cols() == nv_ &&
            terms.bias_forces.size() == nv_ && terms.contacts.size() == point_counts_.size();
  for (std::size_t c = 0; ok && c < terms.contacts.size(); ++c) {
    const ContactTerms& contact = terms.contacts[c];
    const Eigen::Index rows = 3 * point_counts_[c];
    ok = contact.support_jacobian.rows() == 6 && contact.support_jacobian.cols() == nv_ &&
         contact.support_drift.size() == 6 && contact.point_jacobian.rows() == rows &&
         contact.point_jacobian.cols() == nv_ && contact.point_wrench_map.rows() == 6 &&
         contact.point_wrench_map.cols() == rows;
  }
  if (!ok) {
    throw std::invalid_argument(std::string(caller) + ": the terms' sizes differ from nv=" +
                                std::to_string(nv_) + " and the point counts given at construction");
  }
}

// The terms solve() reads, and q̈: finite, or status non_finite_input naming the first that is not.
bool InverseDynamics::start_solve(const Terms& terms,
                                  const Eigen::Ref<const Eigen::VectorXd>& acceleration) {
  result_.status = InverseDynamicsStatus::ok;
  result_.detail = "";
  result_.qp_iterations = 0;
  result_.qp_failures = 0;
  const char* bad = nullptr;
  if (!acceleration.allFinite()) {
    bad = "acceleration is not finite";
  } else if (!terms.mass_matrix.allFinite()) {
    bad = "terms.mass_matrix is not finite";
  } else if (!terms.bias_forces.allFinite()) {
    bad = "terms.bias_forces is not finite";
  } else if (!std::isfinite(terms.total_mass)) {
    bad = "terms.total_mass is not finite";
  } else {
    for (const ContactTerms& contact : terms.contacts) {
      if (!contact.point_jacobian.allFinite() || !contact.support_jacobian.allFinite() ||
          !contact.support_drift.allFinite() || !contact.point_wrench_map.allFinite()) {
        bad = "a contact's Jacobian, drift or wrench map in terms is not finite";
        break;
      }
    }
  }
  if (bad == nullptr) return true;
  result_.status = InverseDynamicsStatus::non_finite_input;
  result_.detail = bad;
  return false;
}

const InverseDynamicsResult& InverseDynamics::solve(
    const Terms& terms, const Eigen::Ref<const Eigen::VectorXd>& acceleration,
    const std::vector<bool>& supports,
    const Eigen::Ref<const Eigen::VectorXd>& friction_coefficients,
    const InverseDynamicsWeights& weights) {
  const std::size_t contact_count = point_counts_.size();
  if (terms.nv() != nv_ || terms.contacts.size() != contact_count ||
      acceleration.size() != nv_ || supports.size() != contact_count ||
      static_cast<std::size_t>(friction_coefficients.size()) != contact_count) {
    throw std::invalid_argument(
        "InverseDynamics.solve: expected nv=" + std::to_string(nv_) + " and " +
        std::to_string(contact_count) + " contacts (terms, acceleration, supports, friction)");
  }
  check_sizes(terms, "InverseDynamics.solve");
  if (!start_solve(terms, acceleration)) return result_;
  if (!std::isfinite(weights.force_regularization) || !std::isfinite(weights.support_weight)) {
    result_.status = InverseDynamicsStatus::non_finite_input;
    result_.detail = "force_regularization or support_weight is not finite";
    return result_;
  }

  // _support_points: the supporting contacts' point rows and μ per point.
  SupportSet& set = support_set(supports);
  bool any_support = false;
  for (std::size_t c = 0, row = 0, point = 0, support = 0; c < contact_count; ++c) {
    if (!supports[c]) continue;
    any_support = true;
    const ContactTerms& contact = terms.contacts[c];
    const Eigen::Index k = point_counts_[c];
    if (!std::isfinite(friction_coefficients[c])) {
      result_.status = InverseDynamicsStatus::non_finite_input;
      result_.detail = "a supporting contact's friction coefficient is not finite";
      return result_;
    }
    set.point_jacobian.middleRows(row, 3 * k) = contact.point_jacobian;
    set.mus.segment(point, k).setConstant(friction_coefficients[c]);
    set.support_jacobian.middleRows(6 * support, 6) = contact.support_jacobian;
    set.support_drift.segment(6 * support, 6) = contact.support_drift;
    row += 3 * k;
    point += k;
    ++support;
  }
  const RowMatrix& M = terms.mass_matrix;
  const Eigen::VectorXd& h = terms.bias_forces;
  generalized_force_.noalias() = M * acceleration;
  generalized_force_ += h;
  const Vector6 root_wrench = generalized_force_.head<kRootDofs>();

  // The exact case: the minimum-norm forces balance the root within the cones (or nothing
  // needs balancing without supports), and the torques are within their limits.
  bool balanced = false;
  if (set.points > 0) balanced = minimum_norm_balance(set, root_wrench);
  if (balanced || !any_support) {
    contact_generalized_force_.noalias() = set.point_jacobian.transpose() * set.point_force;
    torque_ = (generalized_force_ - contact_generalized_force_).tail(nv_ - kRootDofs);
    // np.allclose(w, 0): |w| ≤ 1e-8 elementwise.
    const bool exact = balanced || (root_wrench.array().abs() <= 1e-8).all();
    if (exact && (torque_.array().abs() <= torque_limit_.array()).all()) {
      place_forces(set, supports, terms);
      result_.joint_torque = torque_;
      result_.acceleration = acceleration;
      result_.root_wrench_residual = 0.0;
      result_.saturated_joints = 0;
      result_.path = InverseDynamicsPath::exact;
      return result_;
    }
  }

  // nearest_feasible_motion: the condensed QP, its answer kept if its torques are within
  // limits; else the full QP.
  const double support_weight = weights.support_weight * terms.total_mass;
  bool nearest = condensed_motion(set, terms, acceleration, weights, support_weight);
  if (nearest) {
    contact_generalized_force_.noalias() = set.point_jacobian.transpose() * set.point_force;
    generalized_force_.noalias() = M * motion_;
    generalized_force_ += h;
    torque_ = (generalized_force_ - contact_generalized_force_).tail(nv_ - kRootDofs);
    nearest = (torque_.array().abs() <= torque_limit_.array()).all();
    result_.path = InverseDynamicsPath::condensed_qp;
  }
  if (!nearest) {
    nearest = full_motion(set, terms, acceleration, weights, support_weight);
    result_.path = InverseDynamicsPath::full_qp;
  }
  if (!nearest) {
    // No solver answer: least-squares forces, clipped torques (still consistent below).
    least_squares_balance(set, root_wrench, weights.force_regularization);
    motion_ = acceleration;
    result_.path = InverseDynamicsPath::least_squares;
  }
  place_forces(set, supports, terms);
  contact_generalized_force_.noalias() = set.point_jacobian.transpose() * set.point_force;
  realize(terms, motion_);
  return result_;
}

const InverseDynamicsResult& InverseDynamics::solve_measured(
    const Terms& terms, const Eigen::Ref<const Eigen::VectorXd>& acceleration,
    const Eigen::Ref<const RowMatrix>& measured_wrenches_in_world) {
  const auto contact_count = static_cast<Eigen::Index>(point_counts_.size());
  if (terms.nv() != nv_ || terms.contacts.size() != point_counts_.size() ||
      acceleration.size() != nv_ || measured_wrenches_in_world.rows() != contact_count ||
      measured_wrenches_in_world.cols() != 6) {
    throw std::invalid_argument("InverseDynamics.solve_measured: expected nv=" +
                                std::to_string(nv_) + " and (" + std::to_string(contact_count) +
                                ", 6) measured wrenches");
  }
  check_sizes(terms, "InverseDynamics.solve_measured");
  if (!start_solve(terms, acceleration)) return result_;
  if (!measured_wrenches_in_world.allFinite()) {
    result_.status = InverseDynamicsStatus::non_finite_input;
    result_.detail = "measured_wrenches is not finite";
    return result_;
  }
  // Σ J_supᵀ w over the contacts (the thesis' ground wrenches), then _realize.
  contact_generalized_force_.setZero();
  for (Eigen::Index c = 0; c < contact_count; ++c) {
    contact_generalized_force_.noalias() +=
        terms.contacts[c].support_jacobian.transpose() *
        measured_wrenches_in_world.row(c).transpose();
  }
  result_.contact_force_in_world.setZero();
  result_.contact_wrench_in_world = measured_wrenches_in_world;
  result_.path = InverseDynamicsPath::measured;
  realize(terms, acceleration);
  return result_;
}

// minimum_norm_balance: f = Gᵀ (G Gᵀ)⁻¹ w with G = (J_c)_rootᵀ, into set.point_force, if it
// lies in the friction pyramids (within 1e-9 of the vertical force's scale).
bool InverseDynamics::minimum_norm_balance(SupportSet& set, const Vector6& wrench) {
  const auto root_columns = set.point_jacobian.leftCols<kRootDofs>();  // Gᵀ, (3p, 6)
  set.balance.noalias() = root_columns.transpose() * root_columns;
  root_llt_.compute(set.balance);
  if (root_llt_.info() != Eigen::Success) return false;  // the points cannot balance every wrench
  set.multipliers = root_llt_.solve(wrench);
  set.point_force.noalias() = root_columns * set.multipliers;
  const double tolerance = 1e-9 * std::max(1.0, std::abs(wrench[2]));
  for (Eigen::Index i = 0; i < set.points; ++i) {
    const double mu = set.mus[i] / std::sqrt(2.0);
    const double fx = set.point_force[3 * i], fy = set.point_force[3 * i + 1],
                 fz = set.point_force[3 * i + 2];
    if (!(fx - mu * fz <= tolerance && -fx - mu * fz <= tolerance && fy - mu * fz <= tolerance &&
          -fy - mu * fz <= tolerance && -fz <= tolerance)) {
      return false;
    }
  }
  return true;
}

// _condensed_motion: nearest_feasible_motion without its torque rows, q̈ eliminated.
// q̈ = q̈_des + Δ, N = M + w_s J_supᵀ J_sup, B = M_root, Y = N⁻¹ Bᵀ, K = B Y, Δ₀ = −N⁻¹ g,
// A = (J_cᵀ)_root, c = (M q̈_des + h)_root + B Δ₀; the QP in f:
//   min ½ (A f − c)ᵀ K⁻¹ (A f − c) + ½ ε ‖f‖²  s.t. f in the pyramids,
// then q̈ = q̈_des + Δ₀ + Y K⁻¹ (A f − c), into motion_ and set.point_force.
bool InverseDynamics::condensed_motion(SupportSet& set, const Terms& terms,
                                       const Eigen::Ref<const Eigen::VectorXd>& acceleration,
                                       const InverseDynamicsWeights& weights,
                                       double support_weight) {
  const RowMatrix& M = terms.mass_matrix;
  const Eigen::VectorXd& h = terms.bias_forces;
  condensed_hessian_ = M;
  if (set.contacts > 0) {
    condensed_hessian_.noalias() +=
        support_weight * (set.support_jacobian.transpose() * set.support_jacobian);
  }
  condensed_llt_.compute(condensed_hessian_);
  if (condensed_llt_.info() != Eigen::Success) return false;
  const auto root = M.topRows<kRootDofs>();  // B = M_root, (6, nv)
  condensed_rhs_.leftCols<kRootDofs>() = root.transpose();
  if (set.contacts > 0) {
    // −w_s J_supᵀ (J_sup q̈_des + J̇_sup q̇)
    set.support_acceleration.noalias() = set.support_jacobian * acceleration;
    set.support_acceleration += set.support_drift;
    condensed_rhs_.col(kRootDofs).noalias() =
        -support_weight * (set.support_jacobian.transpose() * set.support_acceleration);
  } else {
    condensed_rhs_.col(kRootDofs).setZero();
  }
  condensed_llt_.solveInPlace(condensed_rhs_);
  const auto Y = condensed_rhs_.leftCols<kRootDofs>();
  const auto delta_free = condensed_rhs_.col(kRootDofs);
  Eigen::Matrix<double, 6, 6> K;
  K.noalias() = root * Y;
  Vector6 c;
  c.noalias() = root * acceleration;
  c += h.head<kRootDofs>();
  c.noalias() += root * delta_free;
  root_llt_.compute(K);
  if (root_llt_.info() != Eigen::Success) return false;
  const auto A = set.point_jacobian.leftCols<kRootDofs>().transpose();  // (6, 3p)
  set.k_inv_a = A;
  root_llt_.solveInPlace(set.k_inv_a);
  set.force_hessian.noalias() = A.transpose() * set.k_inv_a;
  set.force_hessian.diagonal().array() += weights.force_regularization;
  set.force_gradient.noalias() = set.k_inv_a.transpose() * c;  // −(K⁻¹A)ᵀ c: negated below
  set.force_gradient = -set.force_gradient;
  for (Eigen::Index i = 0; i < set.points; ++i) write_pyramid(set.cones, i, set.mus[i]);
  set.cone_upper.setZero();
  if (!solve_qp(set.force_qp, workspace_allocations_, result_, set.force_hessian, set.force_gradient,
                set.cones, set.cone_upper, nullptr, nullptr, set.point_force)) {
    return false;
  }
  Vector6 residual;
  residual.noalias() = A * set.point_force;
  residual -= c;
  root_llt_.solveInPlace(residual);
  motion_ = acceleration + delta_free;
  motion_.noalias() += Y * residual;
  return true;
}

// nearest_feasible_motion's full QP in x = [q̈; f]:
//   min ½ ‖q̈ − q̈_des‖²_M + ½ w_s ‖J_sup q̈ + J̇_sup q̇‖² + ½ ε ‖f‖²
//   s.t. (M q̈ + h − J_cᵀ f)_root = 0, f in the pyramids, |(M q̈ + h − J_cᵀ f)_joints| ≤ τ_max.
bool InverseDynamics::full_motion(SupportSet& set, const Terms& terms,
                                  const Eigen::Ref<const Eigen::VectorXd>& acceleration,
                                  const InverseDynamicsWeights& weights, double support_weight) {
  const RowMatrix& M = terms.mass_matrix;
  const Eigen::VectorXd& h = terms.bias_forces;
  const Eigen::Index nv = nv_, forces = 3 * set.points, joints = nv_ - kRootDofs;
  auto hessian_motion = set.full_hessian.topLeftCorner(nv, nv);
  hessian_motion = M;
  hessian_motion.noalias() +=
      support_weight * (set.support_jacobian.transpose() * set.support_jacobian);
  set.full_hessian.bottomRightCorner(forces, forces).diagonal().setConstant(
      weights.force_regularization);
  auto gradient_motion = set.full_gradient.head(nv);
  gradient_motion.noalias() = support_weight * (set.support_jacobian.transpose() * set.support_drift);
  gradient_motion.noalias() -= M * acceleration;
  set.full_gradient.tail(forces).setZero();
  // (M q̈ + h − J_cᵀ f) = [root wrench; τ]: the root rows are the equality.
  set.full_equality.leftCols(nv) = M.topRows<kRootDofs>();
  set.full_equality.rightCols(forces) =
      -set.point_jacobian.leftCols<kRootDofs>().transpose();
  set.full_equality_rhs = -h.head<kRootDofs>();
  // Rows [0 | pyramids] (the zero block stays as constructed), then ±[M_joints | −J_jointsᵀ].
  auto& inequality = set.full_inequality;
  auto cone_block = inequality.block(0, nv, 5 * set.points, forces);
  for (Eigen::Index i = 0; i < set.points; ++i) write_pyramid(cone_block, i, set.mus[i]);
  const Eigen::Index upper_rows = 5 * set.points;
  inequality.block(upper_rows, 0, joints, nv) = M.bottomRows(joints);
  inequality.block(upper_rows, nv, joints, forces) =
      -set.point_jacobian.rightCols(joints).transpose();
  inequality.block(upper_rows + joints, 0, joints, nv) = -M.bottomRows(joints);
  inequality.block(upper_rows + joints, nv, joints, forces) =
      set.point_jacobian.rightCols(joints).transpose();
  set.full_upper.head(upper_rows).setZero();
  set.full_upper.segment(upper_rows, joints) = torque_limit_ - h.tail(joints);
  set.full_upper.tail(joints) = torque_limit_ + h.tail(joints);
  if (!solve_qp(set.full_qp, workspace_allocations_, result_, set.full_hessian, set.full_gradient,
                set.full_inequality, set.full_upper, &set.full_equality,
                &set.full_equality_rhs, set.full_solution)) {
    return false;
  }
  motion_ = set.full_solution.head(nv);
  set.point_force = set.full_solution.tail(forces);
  return true;
}

// _least_squares_balance: min ‖G f − w‖² + ε ‖f‖² over the cones (zeros if the solver fails).
void InverseDynamics::least_squares_balance(SupportSet& set, const Vector6& wrench,
                                            double regularization) {
  if (set.points == 0) return;  // point_force is empty
  const auto root_columns = set.point_jacobian.leftCols<kRootDofs>();  // Gᵀ, (3p, 6)
  set.force_hessian.noalias() = root_columns * root_columns.transpose();
  set.force_hessian.diagonal().array() += regularization;
  set.force_gradient.noalias() = root_columns * wrench;  // −G w: negated below
  set.force_gradient = -set.force_gradient;
  for (Eigen::Index i = 0; i < set.points; ++i) write_pyramid(set.cones, i, set.mus[i]);
  set.cone_upper.setZero();
  if (!solve_qp(set.force_qp, workspace_allocations_, result_, set.force_hessian, set.force_gradient,
                set.cones, set.cone_upper, nullptr, nullptr, set.point_force)) {
    set.point_force.setZero();
  }
}

// forces[mask] = f, and wrenches_from_point_forces: per contact W f_c = [Σ f; Σ r × f].
void InverseDynamics::place_forces(const SupportSet& set, const std::vector<bool>& supports,
                                   const Terms& terms) {
  Points& forces = result_.contact_force_in_world;
  forces.setZero();
  Eigen::Index column = 0;
  for (std::size_t c = 0; c < supports.size(); ++c) {
    const Eigen::Index k = point_counts_[c];
    if (supports[c]) {
      for (Eigen::Index i = 0; i < k; ++i) {
        forces.row(point_starts_[c] + i) = set.point_force.segment<3>(column + 3 * i).transpose();
      }
      column += 3 * k;
    }
    if (k == 0) {
      result_.contact_wrench_in_world.row(c).setZero();
      continue;
    }
    const Eigen::Map<const Eigen::VectorXd> contact_forces(forces.row(point_starts_[c]).data(),
                                                           3 * k);
    // Into the row in place (a transposed product would be evaluated into a temporary).
    Eigen::Map<Vector6> wrench(result_.contact_wrench_in_world.row(c).data());
    wrench.noalias() = terms.contacts[c].point_wrench_map * contact_forces;
  }
}

// _realize: clip τ for `acceleration` and set the q̈ = M⁻¹ (Sᵀ τ + J_cᵀ f − h) it makes.
// Reads contact_generalized_force_ (J_cᵀ f); writes every field of result_ but the forces.
void InverseDynamics::realize(const Terms& terms,
                              const Eigen::Ref<const Eigen::VectorXd>& acceleration) {
  const RowMatrix& M = terms.mass_matrix;
  const Eigen::VectorXd& h = terms.bias_forces;
  generalized_force_.noalias() = M * acceleration;
  generalized_force_ += h;
  generalized_force_ -= contact_generalized_force_;  // [root wrench; τ unclipped]
  result_.root_wrench_residual = generalized_force_.head<kRootDofs>().norm();
  const auto torque_unclipped = generalized_force_.tail(nv_ - kRootDofs);
  result_.joint_torque = torque_unclipped.cwiseMax(-torque_limit_).cwiseMin(torque_limit_);
  result_.saturated_joints = static_cast<int>(
      ((result_.joint_torque - torque_unclipped).array().abs() > kSaturationTolerance).count());
  applied_ = contact_generalized_force_ - h;
  applied_.tail(nv_ - kRootDofs) += result_.joint_torque;
  mass_llt_.compute(M);
  if (mass_llt_.info() != Eigen::Success) {
    result_.status = InverseDynamicsStatus::mass_matrix_not_positive;
    result_.detail = "the mass matrix is not positive definite";
    return;
  }
  result_.acceleration = applied_;
  mass_llt_.solveInPlace(result_.acceleration);
}

}  // namespace poise
