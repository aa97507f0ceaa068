// The contact-aided right-invariant EKF of the IMU path, as controller_server/estimation/:
// BaseEstimator (base_estimator.py, the filter) and ImuBaseEstimator (imu_base.py, one
// session's tick: joints, contact flags and the IMU reading in, the base estimate out).
//
// Hartley, Ghaffari, Eustice, Grizzle, "Contact-aided invariant extended Kalman filtering for
// robot state estimation", IJRR 39(4), 2020 (arXiv:1904.09251), with the IMU biases appended
// outside the group (their "imperfect IMU" variant). State X = (R, v, p, d_1 … d_K) in
// SE_{2+K}(3) (R = R_WI, v and p of the IMU point in W, d_k the stance contact points in W),
// biases b = [b_g, b_a] in I; error η = X̂ X⁻¹ = exp(ξ), ζ = b̂ − b, covariance order
// [ξ_R, ξ_v, ξ_p, ζ_g, ζ_a, ξ_d1 … ξ_dK]. The Python modules are the specification: the
// same equations in the same order, and the same EstimatorInputError (field and message) on
// the same inputs, before anything changes.
//
// Sizes: at most kMaxContacts stance contacts (protocol MAX_CONTACTS), so every matrix has a
// compile-time maximum size and lives inside the object: no heap allocation per tick.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/LU>

#include "dynamics_core.hpp"
#include "leg_kinematics.hpp"

namespace poise {

inline constexpr int kMaxContacts = 16;                 // protocol.messages.MAX_CONTACTS
inline constexpr int kMaxStateDim = 15 + 3 * kMaxContacts;  // ξ and ζ
inline constexpr int kMaxRows = 4 * kMaxContacts;           // 3 kinematic + 1 ground per contact

using StateMatrix =
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, kMaxStateDim, kMaxStateDim>;
using StateVector = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, kMaxStateDim, 1>;
// [v, p, d_1 … d_K] as columns: the vectors of X.
using GroupColumns = Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::ColMajor, 3, 2 + kMaxContacts>;
using GainMatrix =
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, kMaxStateDim, kMaxRows>;
using GainTransposeMatrix =
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, kMaxRows, kMaxStateDim>;
using InnovationMatrix =
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, kMaxRows, kMaxRows>;
using InnovationVector = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, kMaxRows, 1>;
using Vector6d = Eigen::Matrix<double, 6, 1>;
using Matrix15d = Eigen::Matrix<double, 15, 15, Eigen::RowMajor>;

// estimate.EstimatorNoise: continuous-time densities; flat_ground empty for None.
struct EstimatorNoise {
  double gyro_noise_density;      // rad/s/√Hz
  double accel_noise_density;     // m/s²/√Hz
  double gyro_bias_random_walk;   // rad/s²/√Hz
  double accel_bias_random_walk;  // m/s³/√Hz
  double joint_position_noise;    // rad, 1σ
  double contact_position_noise;  // m, 1σ
  double contact_slip_random_walk;  // m/s/√Hz
  std::optional<double> flat_ground;  // m, 1σ
};

// estimate.EstimatorPrior: initial 1σ (conventional errors, world frame).
struct EstimatorPrior {
  double roll_pitch_rad, yaw_rad, velocity, position, gyro_bias, gyro_bias_at_rest;
  bool still_at_start;
  double accel_bias;
};

// estimate.ImuMount: R_BI (IMU axes in B) and r_BI (IMU origin in B, m).
struct ImuMount {
  Eigen::Matrix3d rotation_imu_to_base;
  Eigen::Vector3d position_imu_in_base;
};

// errors.EstimatorInputError: `field` (the estimator's input name) and `detail`, the same
// words as the Python's (numbers as Python prints them).
class EstimatorInputError : public std::invalid_argument {
 public:
  EstimatorInputError(std::string field, std::string detail)
      : std::invalid_argument(field + ": " + detail),
        field_(std::move(field)),
        detail_(std::move(detail)) {}
  const std::string& field() const { return field_; }
  const std::string& detail() const { return detail_; }

 private:
  std::string field_, detail_;
};

// The contact flags of a tick: bit k for contact k, and how many were given.
struct ContactFlags {
  std::uint32_t mask = 0;
  std::size_t count = 0;
  bool operator[](std::size_t k) const { return (mask >> k & 1U) != 0; }
};

// BaseEstimate: the base state, its (15, 15) covariance and the stance contact points.
struct BaseEstimateOut {
  Eigen::Vector3d position_base_in_world;
  Eigen::Vector4d orientation_base_in_world_xyzw;
  Eigen::Vector3d linear_velocity_base_in_world;
  Eigen::Vector3d angular_velocity_base_in_base;
  Eigen::Vector3d gyro_bias_in_imu;
  Eigen::Vector3d accel_bias_in_imu;
  std::vector<int> stance;                 // contact index of each point below
  Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::ColMajor, 3, kMaxContacts> position_contacts_in_world;
  Matrix15d covariance;  // [δθ_world, δv_base, δp_base, δb_g, δb_a]
};

// The filter's whole state (to hand it between the compiled and the Python kernels).
struct FilterState {
  Eigen::Matrix3d rotation;        // R_WI
  GroupColumns columns;            // [v, p, d_1 …]
  Vector6d bias;                   // [b_g, b_a] in I
  StateMatrix covariance;
  std::vector<int> stance;         // contact index of each d_k
  Eigen::Vector3d gyro_reading;    // last raw gyro
  bool initialized = false;
};

// base_estimator.BaseEstimator: the filter on SE_{2+K}(3) with IMU biases.
class BaseEstimator {
 public:
  // Throws EstimatorInputError for a mount that is no rotation or a bad max_time_step_s.
  BaseEstimator(std::size_t contact_count, const ImuMount& mount, const EstimatorNoise& noise,
                double gravity, double max_time_step_s);

  void reset();
  bool initialized() const { return initialized_; }

  // Start standing: orientation from `orientation_base_in_world_xyzw` (size 4) when given,
  // else levelled on `specific_force_imu_in_imu`; the lowest stance point at z = 0.
  void initialize(const std::vector<ContactPoint>& kinematics, const ContactFlags& flags,
                  const Eigen::Ref<const Eigen::VectorXd>* specific_force_imu_in_imu,
                  const Eigen::Ref<const Eigen::VectorXd>* orientation_base_in_world_xyzw,
                  const Eigen::Ref<const Eigen::VectorXd>* angular_velocity_imu_in_imu,
                  const EstimatorPrior& prior);
  // Hartley et al. 2020, IMU propagation, over dt s.
  void propagate(const Eigen::Ref<const Eigen::VectorXd>& angular_velocity_imu_in_imu,
                 const Eigen::Ref<const Eigen::VectorXd>& specific_force_imu_in_imu, double dt);
  // Leg-kinematics correction, then contact bookkeeping (Hartley et al. 2020).
  void correct(const std::vector<ContactPoint>& kinematics, const ContactFlags& flags);
  // Marginalise the contacts whose bit is set, if in stance.
  void forget_contacts(std::uint32_t contacts);
  // Propagate and correct (BaseEstimator.step once initialised: ImuBaseEstimator initialises).
  void step(const Eigen::Ref<const Eigen::VectorXd>& angular_velocity_imu_in_imu,
            const Eigen::Ref<const Eigen::VectorXd>& specific_force_imu_in_imu, double dt,
            const std::vector<ContactPoint>& kinematics, const ContactFlags& flags);
  void estimate(BaseEstimateOut& out) const;

  // R_WB now (R_BIᵀ before initialisation, as the Python's identity R_WI gives).
  Eigen::Matrix3d rotation_base_in_world() const {
    return rotation_ * mount_.rotation_imu_to_base.transpose();
  }
  FilterState state() const;
  // Throws std::invalid_argument for inconsistent sizes.
  void set_state(const FilterState& state);

 private:
  void check_kinematics(const std::vector<ContactPoint>& kinematics,
                        const ContactFlags& flags) const;
  void require_initialized() const;
  void measure(const std::vector<ContactPoint>& kinematics);
  void keep_contacts(const int* kept, int count);
  void update();
  void add_contact(int contact);
  int dim() const { return 15 + 3 * static_cast<int>(stance_.size()); }

  std::size_t contact_count_;
  ImuMount mount_;
  EstimatorNoise noise_;
  Eigen::Vector3d gravity_;
  double max_time_step_s_;

  // The state.
  Eigen::Matrix3d rotation_;
  GroupColumns columns_;
  Vector6d bias_;
  StateMatrix covariance_;
  std::vector<int> stance_;  // capacity kMaxContacts, reserved once
  Eigen::Vector3d gyro_reading_;
  bool initialized_ = false;

  // Workspaces (sizes within their maxima: no allocation).
  std::vector<Eigen::Vector3d> measured_y_;           // y_k per contact, in I
  std::vector<Eigen::Matrix3d> measured_covariance_;  // its covariance, in I
  StateMatrix offset_, phi_g_, noise_term_, scratch_;  // Φ − I, Φ G, Q_d / dt, scratch
  GainMatrix p_ht_, gain_;
  GainTransposeMatrix gain_transpose_;  // S⁻¹ H P
  InnovationMatrix innovation_covariance_;
  InnovationVector innovation_;
  StateVector delta_;
  Eigen::LLT<InnovationMatrix> llt_;
  Eigen::PartialPivLU<InnovationMatrix> lu_;
};

// imu_base.ImuBaseEstimator: one session's tick, from the joints, contact flags and IMU.
class ImuBaseEstimator {
 public:
  ImuBaseEstimator(std::shared_ptr<const Model> model, std::vector<pinocchio::FrameIndex> frame_ids,
                   std::vector<Points> corners_in_frame, const ImuMount& mount,
                   const EstimatorNoise& noise, const EstimatorPrior& level_prior,
                   const EstimatorPrior& ahrs_prior, double gravity, double max_state_gap_s,
                   double grounded_tolerance_m);

  // The estimate at time_s into `out`. `orientation_imu_in_world_xyzw` may be null. Throws
  // EstimatorInputError (the estimator's field names) as the Python: a gap restarts the
  // filter at the next tick, other errors leave it as the Python leaves it.
  void step(double time_s, const Eigen::Ref<const Eigen::VectorXd>& joint_position,
            const ContactFlags& flags, const Eigen::Ref<const Eigen::VectorXd>& angular_velocity_imu_in_imu,
            const Eigen::Ref<const Eigen::VectorXd>& linear_acceleration_imu_in_imu,
            const Eigen::Ref<const Eigen::VectorXd>* orientation_imu_in_world_xyzw,
            BaseEstimateOut& out);

  std::size_t contact_count() const { return kinematics_.contact_count(); }
  const Model& model() const { return kinematics_.model(); }
  BaseEstimator& filter() { return filter_; }
  const BaseEstimator& filter() const { return filter_; }
  double time_s() const { return time_s_; }
  // Each contact's corners in use (empty before the first tick).
  const std::vector<CornerSet>& corners() const { return corners_; }
  void set_session_state(double time_s, const std::vector<CornerSet>& corners);
  std::mutex& mutex() { return *mutex_; }

 private:
  void initialize(const ContactFlags& flags,
                  const Eigen::Ref<const Eigen::VectorXd>& angular_velocity_imu_in_imu,
                  const Eigen::Ref<const Eigen::VectorXd>& linear_acceleration_imu_in_imu,
                  const Eigen::Ref<const Eigen::VectorXd>* orientation_imu_in_world_xyzw);

  GroundedLegKinematics kinematics_;
  BaseEstimator filter_;
  ImuMount mount_;
  EstimatorPrior level_prior_, ahrs_prior_;
  double max_state_gap_s_;
  double time_s_ = 0.0;
  std::vector<CornerSet> corners_;  // empty: none yet

  Eigen::VectorXd q_;                       // [0 0 0 0 0 0 1, joints], (nq,)
  std::vector<ContactPoint> points_;        // this tick's measurement, per contact
  std::vector<CornerSet> used_;             // this tick's corners, per contact
  std::unique_ptr<std::mutex> mutex_ = std::make_unique<std::mutex>();
};

// Python's repr of a float (shortest round trip: 0.1, 1e-05, nan, -inf), for the messages.
std::string python_repr(double value);

}  // namespace poise
