// The weighted controller's optimizer in C++ (controller_server/controllers/momentum.py,
// MomentumController._optimize, with the tasks of controller_server/tasks/ it stacks):
// Macchietto 2008, eq. 5.1, over x = q̈:
//
//   min  β_t C_t + β_bl C_bl + β_ba C_ba + Σ C_p   s.t.  J_sup q̈ + J̇_sup q̇ = 0
//
//   C_t   tracking toward q_ref (eq. 5.3–5.4), gains raised by soft limits (eq. 6.5–6.6);
//   C_bl  linear momentum toward c_des over the supports (eq. 5.9–5.10), limited to the
//         rate whose COP stays inside the support polygon (admissible rate);
//   C_ba  angular momentum damped (eq. 5.15–5.16), weight β_0 + γ ‖p − g‖ (eq. 5.17);
//   C_p   point-acceleration targets (eq. 6.1–6.3),
//
// solved by the KKT of App. D with damped least squares (kkt.hpp). The Python tasks stay
// the specification: the same rows, in the same stack order (tracking, linear_momentum,
// angular_momentum, then the points), summed into the same normal equations.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "balance_points.hpp"
#include "dynamics_core.hpp"
#include "kkt.hpp"
#include "terms.hpp"

namespace poise {

// The parameters in force that the optimizer reads (MomentumController.PARAMETERS).
struct WeightedParams {
  double stiffness = 30.0, damping = 11.0;                 // k_s, k_d of eq. 5.3
  double weight_tracking = 1.0;                            // β_t
  double weight_root_orientation = 1.0;                    // W_t² on the root orientation
  Eigen::VectorXd joint_weights;                           // W_t² per joint DoF (nv − 6)
  Eigen::VectorXd reference_configuration;                 // q_ref of the fixed pose (nq)
  double joint_limit_stiffness = 200.0, joint_limit_damping = 20.0;  // l_s, l_d
  double weight_linear_momentum = 10.0;                    // β_bl
  double momentum_stiffness = 20.0, momentum_damping = 9.0;  // eq. 5.9
  Eigen::Vector2d com_offset_xy = Eigen::Vector2d::Zero();  // c_des − s (m)
  double cop_margin = 0.02;                                // m
  double angular_momentum_gain = 3000.0;                   // γ (1/m)
  double angular_momentum_damping = 10.0;                  // k_H (1/s)
  double weight_angular_momentum = 0.0;                    // β_0
  double ground_height = 0.0;                              // m
  Eigen::VectorXd friction_coefficients;                   // μ per contact
  double objective_gain_bound = 500.0, constraint_gain_bound = 1000.0;
};

// A point of a frame toward a position and velocity in world (eq. 6.1–6.3).
struct PointTarget {
  std::string name;  // without the "point:" prefix
  pinocchio::FrameIndex frame_id = 0;
  Eigen::Vector3d offset_in_frame = Eigen::Vector3d::Zero();
  Eigen::Vector3d target_position_in_world = Eigen::Vector3d::Zero();
  Eigen::Vector3d target_velocity_in_world = Eigen::Vector3d::Zero();
  double stiffness = 100.0, damping = 20.0, weight = 1.0;
};

// One objective's rows (A x − b) with one weight per row, kept for the residuals.
struct Rows {
  std::string name;     // the task's (diagnostics key)
  RowMatrix A;          // (m, nv)
  Eigen::VectorXd b;    // (m,)
  double weight = 0.0;  // every row's weight
  bool present = false; // the task had rows at the last optimizer run
};

// What the last optimizer run reports (MomentumController._last_optimizer).
struct OptimizerReport {
  Eigen::Vector3d linear_momentum_rate_desired;   // NaN where not controlled
  Eigen::Vector3d angular_momentum_rate_desired;  // NaN without the objective
  double angular_momentum_weight = 0.0;           // β_ba in force
  KKTResult kkt;
};

class WeightedOptimizer {
 public:
  // `model`: the robot; `contact_frames`: each contact's frame (as DynamicsCore's).
  explicit WeightedOptimizer(const Model& model, std::size_t contact_count);

  // Solves eq. 5.1 at the state whose terms and kinematics (`data`, as DynamicsCore leaves
  // it) are given; x = q̈ is written. `limit_errors`: e per DoF (eq. 6.5–6.6). The
  // tracking reference q_ref, v_ref, a_ref (root position ignored: q's is used).
  // `wrenches`: the ground wrenches the COP and CMP of eq. 5.17 are of, (contacts, 6),
  // or an empty matrix for none.
  bool optimize(const Terms& terms, Data& data, const Eigen::Ref<const Eigen::VectorXd>& q,
                const Eigen::Ref<const Eigen::VectorXd>& v, const std::vector<bool>& supports,
                const WeightedParams& params, const std::vector<PointTarget>& points,
                const Eigen::Ref<const Eigen::VectorXd>& limit_errors,
                const Eigen::Ref<const Eigen::VectorXd>& q_ref,
                const Eigen::Ref<const Eigen::VectorXd>& v_ref,
                const Eigen::Ref<const Eigen::VectorXd>& a_ref,
                const Eigen::Ref<const RowMatrix>& wrenches, double gravity,
                Eigen::Ref<Eigen::VectorXd> x);

  // The support polygon of the supporting contacts' sole points (counter-clockwise).
  void support_polygon(const Terms& terms, const std::vector<bool>& supports, Polygon& hull);
  // The support polygon the last optimizer run built.
  const Polygon& last_support_polygon() const { return polygon_; }

  const OptimizerReport& report() const { return report_; }
  // The report with the KKT's condition numbers estimated (diagnostics only).
  const OptimizerReport& report_with_conditioning() {
    kkt_.estimate_conditioning(report_.kkt);
    return report_;
  }
  // ‖√w (A x − b)‖ of each task at the last optimizer run, in stack order (names: tracking,
  // linear_momentum, angular_momentum, point:<name>), for the tasks that had rows.
  void residuals(const Eigen::Ref<const Eigen::VectorXd>& x,
                 std::vector<std::pair<std::string, double>>& out) const;

 private:
  void add_rows(const Rows& rows);
  void tracking(const Model& model, const Eigen::Ref<const Eigen::VectorXd>& q,
                const Eigen::Ref<const Eigen::VectorXd>& v, const WeightedParams& params,
                const Eigen::Ref<const Eigen::VectorXd>& limit_errors,
                const Eigen::Ref<const Eigen::VectorXd>& q_ref,
                const Eigen::Ref<const Eigen::VectorXd>& v_ref,
                const Eigen::Ref<const Eigen::VectorXd>& a_ref);
  void linear_momentum(const Terms& terms, const Eigen::Ref<const Eigen::VectorXd>& v,
                       const std::vector<bool>& supports, const WeightedParams& params,
                       double gravity);
  void angular_momentum(const Terms& terms, const std::vector<bool>& supports,
                        const WeightedParams& params, const Eigen::Ref<const RowMatrix>& wrenches);
  void point(const Model& model, Data& data, const PointTarget& target, Rows& rows);

  const Model& model_;
  Eigen::VectorXd q_reference_;       // (nq) the reference with q's root position
  Eigen::VectorXd tracking_weight_;   // W_t² per DoF
  Eigen::VectorXd tracking_b_;        // q̈_des of eq. 5.3
  Eigen::VectorXd difference_;        // q_ref ⊖ q
  Rows linear_, angular_;
  std::vector<Rows> points_;
  std::size_t point_count_ = 0;  // point targets at the last run
  Eigen::MatrixXd hessian_;
  Eigen::VectorXd gradient_;
  Eigen::MatrixXd C_;
  Eigen::VectorXd d_;
  Data::Matrix6x frame_jacobian_;
  Points supporting_points_;
  PolygonScratch polygon_scratch_;
  Polygon polygon_, admissible_;
  WeightedKKT kkt_;
  OptimizerReport report_;
};

}  // namespace poise
