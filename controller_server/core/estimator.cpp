#include "estimator.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <utility>

#include <Eigen/Geometry>

#include "lie.hpp"

namespace poise {

// -- messages as the Python writes them -------------------------------------------------

std::string python_repr(double value) {
  if (std::isnan(value)) return "nan";
  if (std::isinf(value)) return value > 0 ? "inf" : "-inf";
  if (value == 0.0) return std::signbit(value) ? "-0.0" : "0.0";
  // The shortest digits that round-trip, as Python's repr; its layout: exponent form when
  // the decimal point is more than 4 places left of the digits or 16 right (float_repr).
  char buffer[64];
  const auto result =
      std::to_chars(buffer, buffer + sizeof buffer, std::abs(value), std::chars_format::scientific);
  const std::string text(buffer, result.ptr);
  const std::size_t e = text.find('e');
  const int exponent = std::atoi(text.c_str() + e + 1);
  std::string digits;
  for (std::size_t i = 0; i < e; ++i) {
    if (text[i] != '.') digits += text[i];
  }
  const int point = exponent + 1;  // digits 0.d₁d₂… × 10^point
  const int count = static_cast<int>(digits.size());
  std::string out = value < 0 ? "-" : "";
  if (point <= -4 || point > 16) {
    out += digits.substr(0, 1);
    if (count > 1) out += "." + digits.substr(1);
    char suffix[8];
    std::snprintf(suffix, sizeof suffix, "e%c%02d", exponent < 0 ? '-' : '+', std::abs(exponent));
    out += suffix;
  } else if (point <= 0) {
    out += "0." + std::string(static_cast<std::size_t>(-point), '0') + digits;
  } else if (point >= count) {
    out += digits + std::string(static_cast<std::size_t>(point - count), '0') + ".0";
  } else {
    out += digits.substr(0, static_cast<std::size_t>(point)) + "." +
           digits.substr(static_cast<std::size_t>(point));
  }
  return out;
}

namespace {

// Python's format(value, spec) for the "%.0f" and "%.3g" the messages use.
std::string format_number(const char* spec, double value) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, spec, value);
  return buffer;
}

// array.tolist() of a vector: "[0.1, nan, 2.0]".
template <typename Vector>
std::string python_list(const Vector& values) {
  std::string out = "[";
  for (Eigen::Index i = 0; i < values.size(); ++i) {
    if (i > 0) out += ", ";
    out += python_repr(values[i]);
  }
  return out + "]";
}

std::string positions_list(const std::vector<ContactPoint>& points) {
  std::string out = "[";
  for (std::size_t k = 0; k < points.size(); ++k) {
    if (k > 0) out += ", ";
    out += python_list(points[k].position_in_base);
  }
  return out + "]";
}

std::string jacobians_list(const std::vector<ContactPoint>& points) {
  std::string out = "[";
  for (std::size_t k = 0; k < points.size(); ++k) {
    if (k > 0) out += ", ";
    out += "[";
    for (Eigen::Index r = 0; r < 3; ++r) {
      if (r > 0) out += ", ";
      out += python_list(points[k].jacobian.row(r));
    }
    out += "]";
  }
  return out + "]";
}

// estimate.checked_array(value, field, (size,)) for a vector.
void check_vector(const Eigen::Ref<const Eigen::VectorXd>& value, const char* field,
                  Eigen::Index size) {
  if (value.size() != size) {
    throw EstimatorInputError(field, "shape (" + std::to_string(value.size()) +
                                         ",), expected (" + std::to_string(size) + ",)");
  }
  if (!value.allFinite()) throw EstimatorInputError(field, "not finite: " + python_list(value));
}

// estimate.level_rotation: R_WB with zero yaw whose R_WBᵀ e_z is the specific force's direction.
Eigen::Matrix3d level_rotation(const Eigen::Vector3d& specific_force_in_base) {
  const double fx = specific_force_in_base.x(), fy = specific_force_in_base.y(),
               fz = specific_force_in_base.z();
  const double roll = std::atan2(fy, fz);
  const double pitch = std::atan2(-fx, std::hypot(fy, fz));
  return lie::so3_exp(Eigen::Vector3d(0.0, pitch, 0.0)) * lie::so3_exp(Eigen::Vector3d(roll, 0.0, 0.0));
}

// inekf.propagate_mean: the IMU dynamics integrated exactly for inputs constant over dt
// (Hartley 2020, propagation): R⁺ = R Γ₀(ω dt), v⁺ = v + (R Γ₁(ω dt) a + g) dt,
// p⁺ = p + v dt + (R Γ₂(ω dt) a + g/2) dt²; contact points stay.
void propagate_mean(Eigen::Matrix3d& rotation, GroupColumns& columns, const Eigen::Vector3d& omega,
                    const Eigen::Vector3d& acceleration, const Eigen::Vector3d& gravity, double dt) {
  const lie::Gammas gammas = lie::so3_gammas(omega * dt);
  const Eigen::Vector3d velocity = columns.col(0), position = columns.col(1);
  columns.col(0) = velocity + (rotation * (gammas.gamma1 * acceleration) + gravity) * dt;
  columns.col(1) = position + velocity * dt +
                   (rotation * (gammas.gamma2 * acceleration) + gravity / 2) * (dt * dt);
  rotation = rotation * gammas.gamma0;
}

}  // namespace

// -- the filter ----------------------------------------------------------------------------

BaseEstimator::BaseEstimator(std::size_t contact_count, const ImuMount& mount,
                             const EstimatorNoise& noise, double gravity, double max_time_step_s)
    : contact_count_(contact_count),
      mount_(mount),
      noise_(noise),
      gravity_(0.0, 0.0, -gravity),
      max_time_step_s_(max_time_step_s),
      measured_y_(contact_count),
      measured_covariance_(contact_count) {
  if (contact_count_ > static_cast<std::size_t>(kMaxContacts)) {
    throw std::invalid_argument("the compiled estimator takes at most " +
                                std::to_string(kMaxContacts) + " contacts, got " +
                                std::to_string(contact_count_));
  }
  const Eigen::Matrix3d& rotation = mount_.rotation_imu_to_base;
  const Eigen::Matrix3d gram = rotation.transpose() * rotation;
  // np.allclose(Rᵀ R, I, atol=1e-6) and det R > 0.
  const bool orthonormal =
      ((gram - Eigen::Matrix3d::Identity()).array().abs() <=
       1e-6 + 1e-5 * Eigen::Matrix3d::Identity().array().abs())
          .all();
  if (!rotation.allFinite() || !orthonormal || !(rotation.determinant() > 0)) {
    throw EstimatorInputError("imu_mount.rotation_imu_to_base",
                              "not a rotation matrix: [" + python_list(rotation.row(0)) + ", " +
                                  python_list(rotation.row(1)) + ", " +
                                  python_list(rotation.row(2)) + "]");
  }
  if (!(max_time_step_s > 0)) {
    throw EstimatorInputError("max_time_step_s",
                              "max_time_step_s=" + python_repr(max_time_step_s) + " must be positive");
  }
  stance_.reserve(kMaxContacts);
  reset();
}

void BaseEstimator::reset() {
  rotation_.setIdentity();
  columns_.setZero(3, 2);
  bias_.setZero();
  covariance_.setZero(15, 15);
  stance_.clear();
  gyro_reading_.setZero();
  initialized_ = false;
}

void BaseEstimator::require_initialized() const {
  if (!initialized_) {
    throw EstimatorInputError("state", "the estimator is not initialised: call initialize");
  }
}

void BaseEstimator::check_kinematics(const std::vector<ContactPoint>& kinematics,
                                     const ContactFlags& flags) const {
  for (const ContactPoint& point : kinematics) {
    if (!point.position_in_base.allFinite()) {
      throw EstimatorInputError("kinematics.position_points_in_base",
                                "not finite: " + positions_list(kinematics));
    }
  }
  for (const ContactPoint& point : kinematics) {
    if (!point.jacobian.allFinite()) {
      throw EstimatorInputError("kinematics.jacobians", "not finite: " + jacobians_list(kinematics));
    }
  }
  if (flags.count != contact_count_) {
    throw EstimatorInputError("contact_flags", std::to_string(flags.count) + " flags for " +
                                                   std::to_string(contact_count_) + " contacts");
  }
}

// y = R_BIᵀ (s − r_BI) and its covariance in I, R_BIᵀ (σ_α² J Jᵀ + σ_s² I) R_BI (encoders and
// model error), for every contact (base_estimator._measurement_in_imu).
void BaseEstimator::measure(const std::vector<ContactPoint>& kinematics) {
  const Eigen::Matrix3d& rotation = mount_.rotation_imu_to_base;
  const double joint_variance = noise_.joint_position_noise * noise_.joint_position_noise;
  const double point_variance = noise_.contact_position_noise * noise_.contact_position_noise;
  for (std::size_t k = 0; k < contact_count_; ++k) {
    const ContactPoint& point = kinematics[k];
    Eigen::Matrix3d covariance_in_base;
    covariance_in_base.noalias() = point.jacobian * point.jacobian.transpose();
    covariance_in_base *= joint_variance;
    covariance_in_base.diagonal().array() += point_variance;
    measured_y_[k] = rotation.transpose() * (point.position_in_base - mount_.position_imu_in_base);
    measured_covariance_[k] = (rotation.transpose() * covariance_in_base) * rotation;
  }
}

void BaseEstimator::initialize(const std::vector<ContactPoint>& kinematics,
                               const ContactFlags& flags,
                               const Eigen::Ref<const Eigen::VectorXd>* specific_force_imu_in_imu,
                               const Eigen::Ref<const Eigen::VectorXd>* orientation_base_in_world_xyzw,
                               const Eigen::Ref<const Eigen::VectorXd>* angular_velocity_imu_in_imu,
                               const EstimatorPrior& prior) {
  check_kinematics(kinematics, flags);
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();
  if (angular_velocity_imu_in_imu != nullptr) {
    check_vector(*angular_velocity_imu_in_imu, "angular_velocity_imu_in_imu", 3);
    gyro = *angular_velocity_imu_in_imu;
  }
  Eigen::Matrix3d rotation_base;
  if (orientation_base_in_world_xyzw != nullptr) {
    check_vector(*orientation_base_in_world_xyzw, "orientation_base_in_world_xyzw", 4);
    const Eigen::Vector4d quaternion = *orientation_base_in_world_xyzw;
    const double norm = std::sqrt(quaternion.dot(quaternion));
    if (!(0.5 < norm && norm < 1.5)) {
      throw EstimatorInputError("orientation_base_in_world_xyzw", "norm " + format_number("%.3g", norm));
    }
    const Eigen::Vector4d unit = quaternion / norm;
    rotation_base = Eigen::Quaterniond(unit[3], unit[0], unit[1], unit[2]).toRotationMatrix();
  } else if (specific_force_imu_in_imu != nullptr) {
    check_vector(*specific_force_imu_in_imu, "specific_force_imu_in_imu", 3);
    const Eigen::Vector3d force = *specific_force_imu_in_imu;
    if (std::sqrt(force.dot(force)) < 0.5 * std::sqrt(gravity_.dot(gravity_))) {
      throw EstimatorInputError("specific_force_imu_in_imu",
                                python_list(force) + " is no gravity reading");
    }
    rotation_base = level_rotation(mount_.rotation_imu_to_base * force);
  } else {
    throw EstimatorInputError("orientation_base_in_world_xyzw",
                              "give an orientation or an accelerometer reading to initialise from");
  }
  // x = y = 0 and the lowest stance contact point on z = 0.
  bool any = false;
  double lowest = 0.0;
  for (std::size_t k = 0; k < contact_count_; ++k) {
    if (!flags[k]) continue;
    const double height = rotation_base.row(2).dot(kinematics[k].position_in_base);
    lowest = any ? std::min(lowest, height) : height;
    any = true;
  }
  if (!any) {
    throw EstimatorInputError("contact_flags", "no stance contact to place the base on; give a position");
  }
  const Eigen::Vector3d position_base(0.0, 0.0, -lowest);

  reset();
  gyro_reading_ = gyro;
  double gyro_bias_sigma = prior.gyro_bias;
  if (prior.still_at_start && angular_velocity_imu_in_imu != nullptr) {
    bias_.head<3>() = gyro;  // still: the reading is the bias
    gyro_bias_sigma = prior.gyro_bias_at_rest;
  }
  rotation_ = rotation_base * mount_.rotation_imu_to_base;  // R_WI = R_WB R_BI
  const Eigen::Vector3d position_imu = position_base + rotation_base * mount_.position_imu_in_base;
  columns_.setZero(3, 2);
  columns_.col(1) = position_imu;
  Eigen::Matrix<double, 15, 1> sigma;
  sigma << prior.roll_pitch_rad, prior.roll_pitch_rad, prior.yaw_rad, Eigen::Vector3d::Constant(prior.velocity),
      Eigen::Vector3d::Constant(prior.position), Eigen::Vector3d::Constant(gyro_bias_sigma),
      Eigen::Vector3d::Constant(prior.accel_bias);
  // Conventional errors δv = ξ_v − [v]× ξ_R, δp = ξ_p − [p]× ξ_R (v = 0 here).
  Eigen::Matrix<double, 15, 15> to_invariant = Eigen::Matrix<double, 15, 15>::Identity();
  to_invariant.block<3, 3>(6, 0) = lie::skew(position_imu);
  const Eigen::Matrix<double, 15, 15> prior_covariance = sigma.array().square().matrix().asDiagonal();
  covariance_ = (to_invariant * prior_covariance) * to_invariant.transpose();
  initialized_ = true;
  correct(kinematics, flags);
}

void BaseEstimator::propagate(const Eigen::Ref<const Eigen::VectorXd>& angular_velocity_imu_in_imu,
                              const Eigen::Ref<const Eigen::VectorXd>& specific_force_imu_in_imu,
                              double dt) {
  check_vector(angular_velocity_imu_in_imu, "angular_velocity_imu_in_imu", 3);
  check_vector(specific_force_imu_in_imu, "specific_force_imu_in_imu", 3);
  if (!std::isfinite(dt)) throw EstimatorInputError("dt", "not finite: " + python_repr(dt));
  if (!(0.0 < dt && dt <= max_time_step_s_)) {
    throw EstimatorInputError("dt", "dt=" + python_repr(dt) + " s not in (0, " +
                                        python_repr(max_time_step_s_) + "]");
  }
  require_initialized();
  const Eigen::Vector3d gyro = angular_velocity_imu_in_imu;
  const Eigen::Vector3d omega = gyro - bias_.head<3>();
  const Eigen::Vector3d accel = specific_force_imu_in_imu - bias_.tail<3>();
  gyro_reading_ = gyro;

  // A and G at the mid-step state: the bias columns then match the exact transition to
  // O(dt³) (A itself changes with the state over the step).
  Eigen::Matrix3d rotation = rotation_;
  GroupColumns middle = columns_;
  propagate_mean(rotation, middle, omega, accel, gravity_, dt / 2);

  // inekf.error_dynamics_matrix: ξ̇ = A ξ + G w with, in blocks of three
  // (0 ξ_R, 1 ξ_v, 2 ξ_p, 3 ζ_g, 4 ζ_a, 5 + k ξ_dk), A₁₀ = [g]×, A₂₁ = I, the bias columns
  // A_i3 = −(Ad_X̂)_i0 (−R, −[v]× R, −[p]× R, −[d_k]× R) and A₁₄ = −R; G = blkdiag(Ad_X̂, I₆)
  // in the state order. inekf.error_transition_matrix: A is nilpotent (A⁴ = 0; the chain
  // ζ → ξ_R → ξ_v → ξ_p has three links), so Φ = exp(A dt) = I + A dt + (A dt)²/2 + (A dt)³/6
  // exactly; `offset_` holds N = Φ − I, whose only blocks (Aᵢⱼ scaled by dt) are these.
  const int n = dim();
  const int contacts = static_cast<int>(stance_.size());
  const Eigen::Matrix3d gravity_x = lie::skew(gravity_) * dt;  // (A dt)₁₀
  const Eigen::Matrix3d a03 = -rotation * dt;
  const Eigen::Matrix3d a13 = -(lie::skew(middle.col(0)) * rotation) * dt;
  const Eigen::Matrix3d a23 = -(lie::skew(middle.col(1)) * rotation) * dt;
  const Eigen::Matrix3d a21_a10 = gravity_x * dt;  // (A dt)₂₁ (A dt)₁₀ = dt [g]× dt
  offset_.setZero(n, n);
  offset_.block<3, 3>(0, 9) = a03;
  offset_.block<3, 3>(3, 0) = gravity_x;
  offset_.block<3, 3>(3, 9) = a13 + (gravity_x * a03) / 2.0;
  offset_.block<3, 3>(3, 12) = a03;                        // (A dt)₁₄ = −R dt
  offset_.block<3, 3>(6, 0) = a21_a10 / 2.0;
  offset_.block<3, 3>(6, 3) = Eigen::Matrix3d::Identity() * dt;
  offset_.block<3, 3>(6, 9) = a23 + (a13 * dt) / 2.0 + (a21_a10 * a03) / 6.0;
  offset_.block<3, 3>(6, 12) = (a03 * dt) / 2.0;
  for (int i = 0; i < contacts; ++i) {
    offset_.block<3, 3>(15 + 3 * i, 9) = -(lie::skew(middle.col(2 + i)) * rotation) * dt;
  }
  // Φ = I + N with N zero outside the columns of ξ_R, ξ_v, ζ_g, ζ_a: Φ P Φᵀ = P' + P'[:, C] N[:, C]ᵀ
  // with P' = P + N[:, C] P[C, :] (C those 12 columns), the products of (I + N) P (I + N)ᵀ
  // without the identity's.
  const auto couple = [&](StateMatrix& out, const StateMatrix& left, const StateMatrix& right,
                          bool transpose_right) {
    // out += left[:, C] right[C, :] (or right[:, C]ᵀ), C = {0 … 5, 9 … 14}.
    if (transpose_right) {
      out.noalias() += left.leftCols<6>() * right.leftCols<6>().transpose();
      out.noalias() += left.middleCols<6>(9) * right.middleCols<6>(9).transpose();
    } else {
      out.noalias() += left.leftCols<6>() * right.topRows<6>();
      out.noalias() += left.middleCols<6>(9) * right.middleRows<6>(9);
    }
  };
  scratch_ = covariance_;
  couple(scratch_, offset_, covariance_, false);  // Φ P
  covariance_ = scratch_;
  couple(covariance_, scratch_, offset_, true);   // Φ P Φᵀ
  // Φ G = G + N G: G's group blocks are Ad_X̂'s at the mid-step state (rows ξ_R: R; ξ_v: [v]× R,
  // R; ξ_p: [p]× R, R; ξ_dk: [d_k]× R, R), its bias block I₆; N G reads G's rows in C only.
  phi_g_.setZero(n, n);
  phi_g_.block<3, 3>(0, 0) = rotation;
  for (int i = 0; i < 2 + contacts; ++i) {
    const int row = i < 2 ? 3 + 3 * i : 15 + 3 * (i - 2);
    phi_g_.block<3, 3>(row, 0) = lie::skew(middle.col(i)) * rotation;
    phi_g_.block<3, 3>(row, row) = rotation;
  }
  phi_g_.block<6, 6>(9, 9).setIdentity();
  const Eigen::Matrix3d velocity_x_rotation = phi_g_.block<3, 3>(3, 0);
  phi_g_.leftCols<3>().noalias() += offset_.middleCols<3>(0) * rotation;
  phi_g_.leftCols<3>().noalias() += offset_.middleCols<3>(3) * velocity_x_rotation;
  phi_g_.middleCols<3>(3).noalias() += offset_.middleCols<3>(3) * rotation;
  phi_g_.middleCols<6>(9) += offset_.middleCols<6>(9);
  // Q = diag(σ_g², σ_a², 0 (ξ_p), σ_bg², σ_ba², σ_slip² …), Q_d = Φ G Q Gᵀ Φᵀ dt: the columns
  // of Φ G but ξ_p's, each weighted by its variance.
  const double gyro_variance = noise_.gyro_noise_density * noise_.gyro_noise_density;
  const double accel_variance = noise_.accel_noise_density * noise_.accel_noise_density;
  const double gyro_walk = noise_.gyro_bias_random_walk * noise_.gyro_bias_random_walk;
  const double accel_walk = noise_.accel_bias_random_walk * noise_.accel_bias_random_walk;
  const double slip = noise_.contact_slip_random_walk * noise_.contact_slip_random_walk;
  scratch_.resize(n, n);
  scratch_.leftCols<3>() = phi_g_.leftCols<3>() * gyro_variance;
  scratch_.middleCols<3>(3) = phi_g_.middleCols<3>(3) * accel_variance;
  scratch_.middleCols<3>(6).setZero();
  scratch_.middleCols<3>(9) = phi_g_.middleCols<3>(9) * gyro_walk;
  scratch_.middleCols<3>(12) = phi_g_.middleCols<3>(12) * accel_walk;
  scratch_.rightCols(n - 15) = phi_g_.rightCols(n - 15) * slip;
  noise_term_.noalias() = scratch_.leftCols<6>() * phi_g_.leftCols<6>().transpose();
  noise_term_.noalias() += scratch_.rightCols(n - 9) * phi_g_.rightCols(n - 9).transpose();
  covariance_ += noise_term_ * dt;

  propagate_mean(rotation_, columns_, omega, accel, gravity_, dt);
}

void BaseEstimator::keep_contacts(const int* kept, int count) {
  int index[kMaxStateDim];
  for (int i = 0; i < 15; ++i) index[i] = i;
  for (int c = 0; c < count; ++c) {
    for (int j = 0; j < 3; ++j) index[15 + 3 * c + j] = 15 + 3 * kept[c] + j;
  }
  const int new_dim = 15 + 3 * count;
  scratch_.resize(new_dim, new_dim);
  for (int j = 0; j < new_dim; ++j) {
    for (int i = 0; i < new_dim; ++i) scratch_(i, j) = covariance_(index[i], index[j]);
  }
  covariance_ = scratch_;
  for (int c = 0; c < count; ++c) {
    columns_.col(2 + c) = columns_.col(2 + kept[c]);  // kept is increasing: c ≤ kept[c]
    stance_[c] = stance_[kept[c]];
  }
  columns_.conservativeResize(3, 2 + count);
  stance_.resize(count);
}

void BaseEstimator::forget_contacts(std::uint32_t contacts) {
  int kept[kMaxContacts];
  int count = 0;
  for (int i = 0; i < static_cast<int>(stance_.size()); ++i) {
    if (!(contacts >> stance_[i] & 1U)) kept[count++] = i;
  }
  if (count < static_cast<int>(stance_.size())) keep_contacts(kept, count);
}

// The kinematic rows z_i = R̂ y − (d̂_i − p̂), H_i = [0, 0, −I, 0, 0, …, I, …] and the
// flat-ground rows z = −d̂_z, H = [(d̂ × e_z)ᵀ, 0, 0, 0, 0, …, e_zᵀ, …] of every stance
// contact (inekf.kinematic_innovation, inekf.ground_innovation), then the EKF update
// X̂⁺ = exp(δ_ξ) X̂, b̂⁺ = b̂ + δ_ζ, δ = K z, P⁺ = P − K H P (Hartley 2020, correction).
// H is a selection of P's rows and columns, so P Hᵀ and H P Hᵀ are read off P.
void BaseEstimator::update() {
  const int n = dim();
  const int count = static_cast<int>(stance_.size());
  const bool ground = noise_.flat_ground.has_value();
  const int rows = 3 * count + (ground ? count : 0);
  p_ht_.resize(n, rows);
  innovation_.resize(rows);
  innovation_covariance_.setZero(rows, rows);
  for (int i = 0; i < count; ++i) {
    const Eigen::Vector3d point = columns_.col(2 + i);
    const int k = stance_[i];
    innovation_.segment<3>(3 * i) =
        rotation_ * measured_y_[k] - (point - columns_.col(1));
    p_ht_.middleCols<3>(3 * i) = covariance_.middleCols<3>(15 + 3 * i) - covariance_.middleCols<3>(6);
    innovation_covariance_.block<3, 3>(3 * i, 3 * i) =
        (rotation_ * measured_covariance_[k]) * rotation_.transpose();
    if (ground) {
      const int row = 3 * count + i;
      innovation_[row] = -point.z();
      p_ht_.col(row) = covariance_.col(0) * point.y() - covariance_.col(1) * point.x() +
                       covariance_.col(17 + 3 * i);
      innovation_covariance_(row, row) = *noise_.flat_ground * *noise_.flat_ground;
    }
  }
  // S = H P Hᵀ + N, the rows of H applied to P Hᵀ.
  for (int i = 0; i < count; ++i) {
    innovation_covariance_.middleRows<3>(3 * i) +=
        p_ht_.middleRows<3>(15 + 3 * i) - p_ht_.middleRows<3>(6);
    if (ground) {
      const Eigen::Vector3d point = columns_.col(2 + i);
      innovation_covariance_.row(3 * count + i) +=
          p_ht_.row(0) * point.y() - p_ht_.row(1) * point.x() + p_ht_.row(17 + 3 * i);
    }
  }
  // K = P Hᵀ S⁻¹: S is symmetric positive definite (N is), Cholesky; should round-off have
  // made it indefinite, LU with partial pivoting, as np.linalg.solve.
  llt_.compute(innovation_covariance_);
  gain_transpose_ = p_ht_.transpose();
  if (llt_.info() == Eigen::Success) {
    llt_.solveInPlace(gain_transpose_);
  } else {
    lu_.compute(innovation_covariance_);
    gain_transpose_ = lu_.solve(p_ht_.transpose());
  }
  gain_ = gain_transpose_.transpose();
  delta_.noalias() = gain_ * innovation_;

  // lie.sek3_exp of [δ_ξR, δ_ξv, δ_ξp, δ_ξd…]: (Γ₀(δ_R), Γ₁(δ_R) δ_i).
  const Eigen::Vector3d delta_rotation = delta_.head<3>();
  const lie::Gammas gammas = lie::so3_gammas(delta_rotation);
  rotation_ = gammas.gamma0 * rotation_;
  for (int i = 0; i < 2 + count; ++i) {
    const int row = i < 2 ? 3 + 3 * i : 15 + 3 * (i - 2);
    const Eigen::Vector3d column = columns_.col(i);
    columns_.col(i) = gammas.gamma0 * column + gammas.gamma1 * delta_.segment<3>(row);
  }
  bias_ += delta_.segment<6>(9);
  // P − K S Kᵀ = P − K H P with the optimal gain; symmetrised against round-off.
  covariance_.noalias() -= gain_ * p_ht_.transpose();
  scratch_ = covariance_.transpose();
  covariance_ = 0.5 * (covariance_ + scratch_);
}

// A contact entering stance at d̂ = p̂ + R̂ y, whose error ξ_d = ξ_p + R̂ n copies the ξ_p rows
// (Hartley 2020, adding contacts; base_estimator._add_contact).
void BaseEstimator::add_contact(int contact) {
  const int n = dim();
  covariance_.conservativeResize(n + 3, n + 3);
  covariance_.block(n, 0, 3, n) = covariance_.block(6, 0, 3, n);
  covariance_.block(0, n, n, 3) = covariance_.block(0, 6, n, 3);
  covariance_.block<3, 3>(n, n) = covariance_.block<3, 3>(6, 6) +
      (rotation_ * measured_covariance_[contact]) * rotation_.transpose();
  const int column = static_cast<int>(columns_.cols());
  columns_.conservativeResize(3, column + 1);
  columns_.col(column) = columns_.col(1) + rotation_ * measured_y_[contact];
  stance_.push_back(contact);
}

void BaseEstimator::correct(const std::vector<ContactPoint>& kinematics, const ContactFlags& flags) {
  check_kinematics(kinematics, flags);
  require_initialized();
  int kept[kMaxContacts];
  int count = 0;
  for (int i = 0; i < static_cast<int>(stance_.size()); ++i) {
    if (flags[stance_[i]]) kept[count++] = i;
  }
  if (count < static_cast<int>(stance_.size())) keep_contacts(kept, count);
  measure(kinematics);
  if (!stance_.empty()) update();
  for (std::size_t k = 0; k < contact_count_; ++k) {
    if (flags[k] && std::find(stance_.begin(), stance_.end(), static_cast<int>(k)) == stance_.end()) {
      add_contact(static_cast<int>(k));
    }
  }
}

void BaseEstimator::step(const Eigen::Ref<const Eigen::VectorXd>& angular_velocity_imu_in_imu,
                         const Eigen::Ref<const Eigen::VectorXd>& specific_force_imu_in_imu, double dt,
                         const std::vector<ContactPoint>& kinematics, const ContactFlags& flags) {
  check_kinematics(kinematics, flags);  // before changing anything
  propagate(angular_velocity_imu_in_imu, specific_force_imu_in_imu, dt);
  correct(kinematics, flags);
}

// The base B carries the IMU at R_BI, r_BI: R_WB = R_WI R_BIᵀ, p_B = p_I − R_WB r_BI,
// ω_B = R_BI ω_I, v_B = v_I − R_WB (ω_B × r_BI); the covariance T P Tᵀ of the conventional
// base errors (base_estimator.estimate).
void BaseEstimator::estimate(BaseEstimateOut& out) const {
  require_initialized();
  const Eigen::Matrix3d& mount_rotation = mount_.rotation_imu_to_base;
  const Eigen::Vector3d& offset = mount_.position_imu_in_base;
  const Eigen::Matrix3d rotation_base = rotation_ * mount_rotation.transpose();
  const Eigen::Vector3d angular_velocity = mount_rotation * (gyro_reading_ - bias_.head<3>());
  const Eigen::Vector3d velocity = columns_.col(0) - rotation_base * angular_velocity.cross(offset);
  const Eigen::Vector3d position = columns_.col(1) - rotation_base * offset;
  // Invariant errors to conventional base errors (BaseEstimate.covariance): T P Tᵀ with
  // T = I + E, E's blocks E₁₀ = −[v_B]×, E₁₃ = −R_WB [r_BI]× R_BI, E₂₀ = −[p_B]× (T is zero
  // on the contact columns: P's first 15 rows and columns), as (T P) Tᵀ by E's blocks.
  const Eigen::Matrix3d e10 = -lie::skew(velocity);
  const Eigen::Matrix3d e13 = -(rotation_base * lie::skew(offset)) * mount_rotation;
  const Eigen::Matrix3d e20 = -lie::skew(position);
  Eigen::Matrix<double, 15, 15> t_p = covariance_.topLeftCorner<15, 15>();
  t_p.middleRows<3>(3).noalias() += e10 * t_p.topRows<3>() + e13 * t_p.middleRows<3>(9);
  t_p.middleRows<3>(6).noalias() += e20 * t_p.topRows<3>();
  out.covariance = t_p;
  out.covariance.middleCols<3>(3).noalias() +=
      t_p.leftCols<3>() * e10.transpose() + t_p.middleCols<3>(9) * e13.transpose();
  out.covariance.middleCols<3>(6).noalias() += t_p.leftCols<3>() * e20.transpose();
  Eigen::Quaterniond quaternion(rotation_base);
  quaternion.normalize();
  out.position_base_in_world = position;
  out.orientation_base_in_world_xyzw = quaternion.coeffs();  // x, y, z, w
  out.linear_velocity_base_in_world = velocity;
  out.angular_velocity_base_in_base = angular_velocity;
  out.gyro_bias_in_imu = bias_.head<3>();
  out.accel_bias_in_imu = bias_.tail<3>();
  out.stance.assign(stance_.begin(), stance_.end());
  out.position_contacts_in_world = columns_.rightCols(columns_.cols() - 2);
}

FilterState BaseEstimator::state() const {
  return {rotation_, columns_, bias_, covariance_, stance_, gyro_reading_, initialized_};
}

void BaseEstimator::set_state(const FilterState& state) {
  const Eigen::Index contacts = static_cast<Eigen::Index>(state.stance.size());
  if (state.columns.cols() != 2 + contacts || state.covariance.rows() != 15 + 3 * contacts ||
      state.covariance.cols() != 15 + 3 * contacts || contacts > kMaxContacts) {
    throw std::invalid_argument("inconsistent filter state: " + std::to_string(contacts) +
                                " stance contacts, " + std::to_string(state.columns.cols()) +
                                " columns, covariance " + std::to_string(state.covariance.rows()));
  }
  for (int k : state.stance) {
    if (k < 0 || k >= static_cast<int>(contact_count_)) {
      throw std::invalid_argument("stance contact " + std::to_string(k) + " out of range");
    }
  }
  rotation_ = state.rotation;
  columns_ = state.columns;
  bias_ = state.bias;
  covariance_ = state.covariance;
  stance_.assign(state.stance.begin(), state.stance.end());
  gyro_reading_ = state.gyro_reading;
  initialized_ = state.initialized;
}

// -- one session's tick ----------------------------------------------------------------------

ImuBaseEstimator::ImuBaseEstimator(std::shared_ptr<const Model> model,
                                   std::vector<pinocchio::FrameIndex> frame_ids,
                                   std::vector<Points> corners_in_frame, const ImuMount& mount,
                                   const EstimatorNoise& noise, const EstimatorPrior& level_prior,
                                   const EstimatorPrior& ahrs_prior, double gravity,
                                   double max_state_gap_s, double grounded_tolerance_m)
    : kinematics_(model, std::move(frame_ids), std::move(corners_in_frame), grounded_tolerance_m),
      filter_(kinematics_.contact_count(), mount, noise, gravity, max_state_gap_s),
      mount_(mount),
      level_prior_(level_prior),
      ahrs_prior_(ahrs_prior),
      max_state_gap_s_(max_state_gap_s),
      q_(Eigen::VectorXd::Zero(model->nq)),
      points_(kinematics_.contact_count(),
              ContactPoint{Eigen::Vector3d::Zero(),
                           Eigen::Matrix<double, 3, Eigen::Dynamic>::Zero(3, model->nv - 6)}),
      used_(kinematics_.contact_count(), 0) {
  if (model->nq < 7 || model->nv < 6) {
    throw std::invalid_argument("the model's first joint must be a free flyer");
  }
  corners_.reserve(kinematics_.contact_count());
}

void ImuBaseEstimator::set_session_state(double time_s, const std::vector<CornerSet>& corners) {
  if (!corners.empty() && corners.size() != contact_count()) {
    throw std::invalid_argument("one corner set per contact is needed");
  }
  time_s_ = time_s;
  corners_.assign(corners.begin(), corners.end());
}

void ImuBaseEstimator::initialize(const ContactFlags& flags,
                                  const Eigen::Ref<const Eigen::VectorXd>& angular_velocity_imu_in_imu,
                                  const Eigen::Ref<const Eigen::VectorXd>& linear_acceleration_imu_in_imu,
                                  const Eigen::Ref<const Eigen::VectorXd>* orientation_imu_in_world_xyzw) {
  if (orientation_imu_in_world_xyzw == nullptr) {
    filter_.initialize(points_, flags, &linear_acceleration_imu_in_imu, nullptr,
                       &angular_velocity_imu_in_imu, level_prior_);
    return;
  }
  const Eigen::Ref<const Eigen::VectorXd>& xyzw = *orientation_imu_in_world_xyzw;
  if (xyzw.size() != 4) {
    throw std::invalid_argument("orientation_imu_in_world_xyzw has " + std::to_string(xyzw.size()) +
                                " entries, not 4");
  }
  // As imu_base: the IMU's quaternion normalised, R_WB = R_WI R_BIᵀ, back to a quaternion.
  const Eigen::Quaterniond rotation_imu =
      Eigen::Quaterniond(xyzw[3], xyzw[0], xyzw[1], xyzw[2]).normalized();
  const Eigen::Matrix3d rotation_base =
      rotation_imu.toRotationMatrix() * mount_.rotation_imu_to_base.transpose();
  const Eigen::Vector4d quaternion = Eigen::Quaterniond(rotation_base).coeffs();
  const Eigen::Ref<const Eigen::VectorXd> orientation(quaternion);
  filter_.initialize(points_, flags, nullptr, &orientation, &angular_velocity_imu_in_imu, ahrs_prior_);
}

void ImuBaseEstimator::step(double time_s, const Eigen::Ref<const Eigen::VectorXd>& joint_position,
                            const ContactFlags& flags,
                            const Eigen::Ref<const Eigen::VectorXd>& angular_velocity_imu_in_imu,
                            const Eigen::Ref<const Eigen::VectorXd>& linear_acceleration_imu_in_imu,
                            const Eigen::Ref<const Eigen::VectorXd>* orientation_imu_in_world_xyzw,
                            BaseEstimateOut& out) {
  const Model& model = kinematics_.model();
  if (joint_position.size() != model.nq - 7) {
    throw std::invalid_argument("joint_position has " + std::to_string(joint_position.size()) +
                                " entries, the model " + std::to_string(model.nq - 7));
  }
  // The joints normalised (ball joints' quaternions), the base at the identity.
  q_.head<7>() << 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0;
  q_.tail(model.nq - 7) = joint_position;
  kinematics_.normalize(q_);
  const bool initialized = filter_.initialized();
  const bool have_corners = initialized && corners_.size() == contact_count();
  kinematics_.compute(q_, filter_.rotation_base_in_world(), have_corners ? corners_.data() : nullptr,
                      points_, used_);
  if (!initialized) {
    initialize(flags, angular_velocity_imu_in_imu, linear_acceleration_imu_in_imu,
               orientation_imu_in_world_xyzw);
  } else {
    const double dt = time_s - time_s_;
    if (dt > max_state_gap_s_) {
      filter_.reset();
      throw EstimatorInputError(
          "dt", format_number("%.0f", dt * 1e3) + " ms since the previous state, more than " +
                    format_number("%.0f", max_state_gap_s_ * 1e3) +
                    " ms: the base estimator restarts at the next state (the robot should then "
                    "stand still on its flagged feet)");
    }
    if (!(dt > 0)) {
      throw EstimatorInputError(
          "dt", "time_s " + python_repr(time_s) + " does not advance from " + python_repr(time_s_));
    }
    // A foot whose corners on the ground changed stands on another point now.
    std::uint32_t changed = 0;
    for (std::size_t k = 0; k < contact_count(); ++k) {
      if (used_[k] != corners_[k]) changed |= std::uint32_t{1} << k;
    }
    filter_.forget_contacts(changed);
    filter_.step(angular_velocity_imu_in_imu, linear_acceleration_imu_in_imu, dt, points_, flags);
  }
  filter_.estimate(out);
  time_s_ = time_s;
  corners_.assign(used_.begin(), used_.end());
}

}  // namespace poise
