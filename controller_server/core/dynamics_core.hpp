// Per-tick rigid-body terms of controller_server.dynamics.compute_dynamics_terms, in C++.
//
// The same Pinocchio calls as the Python function, in the same order, so the
// two agree to rounding:
//   computeAllTerms -> M, h = C + G, CoM, total mass, A_g, joint Jacobians
//   computeCentroidalMomentumTimeVariation(q, v, 0) -> h_g = A_g v, Ȧ_g v,
//       and the kinematics of (q, v, q̈ = 0) in data (the drifts read them)
//   updateFramePlacements -> oMf
//   per contact: getFrameJacobian / getFrameVelocity / getFrameClassicalAcceleration
//       in LOCAL_WORLD_ALIGNED, then the sole points fixed to that frame.
#pragma once

#include <cstddef>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <Eigen/Core>

#include <pinocchio/multibody.hpp>

namespace poise {

using Model = pinocchio::Model;
using Data = pinocchio::Data;

// Outputs are row-major so that they become C-ordered numpy arrays, as the
// Python code produces.
using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
// (k, 3) points, one per row.
using Points = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

// A support of the robot: a frame and the sole points fixed to it (in the frame).
struct ContactSpec {
  pinocchio::FrameIndex frame_id;
  Points points_in_frame;  // (k, 3), metres
};

// Output buffers, written in place by DynamicsCore::compute (the caller owns the
// memory: the Python binding points these at fresh numpy arrays). Field names
// are those of DynamicsTerms (dynamics.py) and MomentumRates (momentum.py).
using RowMatrixMap = Eigen::Map<RowMatrix>;
using VectorMap = Eigen::Map<Eigen::VectorXd>;
using Vector3Map = Eigen::Map<Eigen::Vector3d>;
using PointsMap = Eigen::Map<Points>;

struct ContactOut {
  RowMatrixMap support_jacobian;       // (6, nv): [v_origin; ω] of the frame, world axes
  VectorMap support_drift;             // (6,): J̇ q̇, classical accelerations at q̈ = 0
  RowMatrixMap point_jacobian;         // (3k, nv): velocity of each point, world axes
  VectorMap point_drift;               // (3k,): point accelerations at q̈ = 0
  RowMatrixMap point_wrench_map;       // (6, 3k): W = [I … I; [r₁]× … [r_k]×]
  PointsMap position_points_in_world;  // (k, 3)
};

struct TermsOut {
  RowMatrixMap mass_matrix;                  // (nv, nv), symmetric
  VectorMap bias_forces;                     // (nv,): h = C(q, v) q̇ + g(q)
  Vector3Map position_com_in_world;
  double total_mass;                         // kg
  std::vector<ContactOut> contacts;          // in contact order
  PointsMap position_contact_frames_in_world;  // (contacts, 3)
  RowMatrixMap R;                            // (3, nv): linear rows of A_g
  RowMatrixMap S;                            // (3, nv): angular rows of A_g (about the CoM)
  Vector3Map r_bias;                         // linear momentum rate at q̈ = 0
  Vector3Map s_bias;                         // angular momentum rate at q̈ = 0
  Vector3Map linear_momentum;                // L = R q̇
  Vector3Map angular_momentum;               // H = S q̇
};

// Reads a model written by Python's `pin.Model.saveToString()` (Boost text archive).
std::shared_ptr<const Model> model_from_string(const std::string& text);

// One robot's model (shared, read only) and one session's workspace (Data and
// scratch buffers, allocated once). compute() may run without the GIL: a mutex
// serialises calls on the same DynamicsCore; distinct cores run in parallel.
class DynamicsCore {
 public:
  DynamicsCore(std::shared_ptr<const Model> model, std::vector<ContactSpec> contacts);

  // Evaluates every term at (q, v) into `out`, whose maps must have the sizes
  // above (nv, and each contact's point count). Throws std::invalid_argument on
  // bad sizes of q or v.
  void compute(const Eigen::Ref<const Eigen::VectorXd>& q,
               const Eigen::Ref<const Eigen::VectorXd>& v, TermsOut& out);

  // The Pinocchio calls of compute() alone, writing no outputs (for timing).
  void compute_in_place(const Eigen::Ref<const Eigen::VectorXd>& q,
                        const Eigen::Ref<const Eigen::VectorXd>& v);

  // A new workspace on the same (shared) model: one per session.
  DynamicsCore clone() const { return DynamicsCore(model_, contacts_); }

  const Model& model() const { return *model_; }
  // This workspace's Pinocchio data: after compute(), the state's kinematics (joint and
  // frame placements, velocities, accelerations at q̈ = 0, joint Jacobians).
  const Data& data() const { return data_; }
  Data& data() { return data_; }  // frame Jacobians write the frame's placement
  const std::vector<ContactSpec>& contacts() const { return contacts_; }
  void check_sizes(const Eigen::Ref<const Eigen::VectorXd>& q,
                   const Eigen::Ref<const Eigen::VectorXd>& v) const;

 private:
  void run_pinocchio(const Eigen::Ref<const Eigen::VectorXd>& q,
                     const Eigen::Ref<const Eigen::VectorXd>& v);

  std::shared_ptr<const Model> model_;
  std::vector<ContactSpec> contacts_;
  Data data_;
  Eigen::VectorXd zero_acceleration_;   // q̈ = 0, (nv,)
  Data::Matrix6x frame_jacobian_;       // scratch (6, nv)
  std::unique_ptr<std::mutex> mutex_ = std::make_unique<std::mutex>();
};

}  // namespace poise
