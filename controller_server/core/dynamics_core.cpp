#include "dynamics_core.hpp"
#include "frame_point.hpp"

#include <stdexcept>
#include <string>
#include <utility>

#include <pinocchio/algorithm/centroidal.hpp>
#include <pinocchio/algorithm/compute-all-terms.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/spatial.hpp>

namespace poise {

namespace {
constexpr auto kWorldAligned = pinocchio::LOCAL_WORLD_ALIGNED;
}  // namespace

DynamicsCore::DynamicsCore(std::shared_ptr<const Model> model, std::vector<ContactSpec> contacts)
    : model_(std::move(model)),
      contacts_(std::move(contacts)),
      data_(*model_),
      zero_acceleration_(Eigen::VectorXd::Zero(model_->nv)),
      frame_jacobian_(Data::Matrix6x::Zero(6, model_->nv)) {
  for (const ContactSpec& contact : contacts_) {
    if (contact.frame_id >= static_cast<pinocchio::FrameIndex>(model_->nframes)) {
      throw std::invalid_argument("contact frame id " + std::to_string(contact.frame_id) +
                                  " is not below nframes = " + std::to_string(model_->nframes));
    }
  }
}

void DynamicsCore::check_sizes(const Eigen::Ref<const Eigen::VectorXd>& q,
                               const Eigen::Ref<const Eigen::VectorXd>& v) const {
  if (q.size() != model_->nq || v.size() != model_->nv) {
    throw std::invalid_argument("expected q of size " + std::to_string(model_->nq) +
                                " and v of size " + std::to_string(model_->nv) + ", got " +
                                std::to_string(q.size()) + " and " + std::to_string(v.size()));
  }
}

void DynamicsCore::run_pinocchio(const Eigen::Ref<const Eigen::VectorXd>& q,
                                 const Eigen::Ref<const Eigen::VectorXd>& v) {
  const Model& model = *model_;
  // Forward kinematics at (q, v), joint Jacobians data.J, the mass matrix data.M
  // (CRBA, upper triangle only), the bias forces data.nle = C(q, v) q̇ + g(q) (RNEA at
  // q̈ = 0), the centre of mass data.com[0] with the subtree masses (data.mass[0] is
  // the total), and the centroidal momentum matrix data.Ag (CCRBA).
  pinocchio::computeAllTerms(model, data_, q, v);
}

void DynamicsCore::compute(const Eigen::Ref<const Eigen::VectorXd>& q,
                           const Eigen::Ref<const Eigen::VectorXd>& v, TermsOut& out) {
  check_sizes(q, v);
  if (out.contacts.size() != contacts_.size() || out.mass_matrix.rows() != model_->nv) {
    throw std::invalid_argument("output buffers do not match the model and contacts");
  }
  std::lock_guard<std::mutex> lock(*mutex_);
  const Model& model = *model_;

  run_pinocchio(q, v);
  // CRBA fills the upper triangle of M: mirror it into the strictly lower one.
  out.mass_matrix = data_.M;
  out.mass_matrix.triangularView<Eigen::StrictlyLower>() = data_.M.transpose();
  out.bias_forces = data_.nle;
  out.position_com_in_world = data_.com[0];
  out.total_mass = data_.mass[0];
  // A_g = [R; S] (momentum.py).
  out.R = data_.Ag.topRows<3>();
  out.S = data_.Ag.bottomRows<3>();

  // The centroidal momentum rate at q̈ = 0, i.e. Ȧ_g q̇ = [r_bias; s_bias]. It runs
  // forward kinematics at (q, v, q̈ = 0) again, so data.a then holds the joint
  // accelerations at q̈ = 0 that the contact drifts are read from, and it sets
  // data.hg = A_g q̇ (the momenta).
  const pinocchio::Force& momentum_rate = pinocchio::computeCentroidalMomentumTimeVariation(
      model, data_, q, v, zero_acceleration_);
  out.r_bias = momentum_rate.linear();
  out.s_bias = momentum_rate.angular();
  out.linear_momentum = data_.hg.linear();
  out.angular_momentum = data_.hg.angular();

  // World placements of every frame, data.oMf, from the joint placements data.oMi.
  pinocchio::updateFramePlacements(model, data_);

  for (std::size_t c = 0; c < contacts_.size(); ++c) {
    const ContactSpec& contact = contacts_[c];
    ContactOut& terms = out.contacts[c];
    const pinocchio::SE3& placement = data_.oMf[contact.frame_id];

    // 6 x nv Jacobian of the frame origin's [linear; angular] velocity in world axes
    // (built from data.J; columns of joints not supporting the frame are left
    // untouched, hence the zeroing).
    frame_jacobian_.setZero();
    pinocchio::getFrameJacobian(model, data_, contact.frame_id, kWorldAligned, frame_jacobian_);
    // Twist of the frame origin, world axes (from data.v).
    const pinocchio::Motion velocity =
        pinocchio::getFrameVelocity(model, data_, contact.frame_id, kWorldAligned);
    // Classical acceleration of the frame origin, world axes, from data.a (q̈ = 0):
    // [a_o + ω × v_o; α] = J̇ q̇, the support drift.
    const pinocchio::Motion drift =
        pinocchio::getFrameClassicalAcceleration(model, data_, contact.frame_id, kWorldAligned);

    terms.support_jacobian = frame_jacobian_;
    terms.support_drift = drift.toVector();
    out.position_contact_frames_in_world.row(static_cast<Eigen::Index>(c)) =
        placement.translation().transpose();

    // Points p = o + r fixed to the frame, r = R p_in_frame in world axes (App. C):
    //   J_p = J_v − [r]× J_ω,  a_p = a_o − [r]× α + ω × (ω × r),
    // i.e. the rows Wᵀ J and Wᵀ J̇q̇ (+ centripetal) of dynamics._points_on_frame.
    const Eigen::Index count = contact.points_in_frame.rows();
    const Points offsets = contact.points_in_frame * placement.rotation().transpose();
    terms.position_points_in_world = offsets.rowwise() + placement.translation().transpose();
    terms.point_wrench_map.setZero();
    const Eigen::Vector3d omega = velocity.angular();
    for (Eigen::Index i = 0; i < count; ++i) {
      const Eigen::Vector3d r = offsets.row(i).transpose();
      terms.point_wrench_map.block<3, 3>(0, 3 * i).setIdentity();
      terms.point_wrench_map.block<3, 3>(3, 3 * i) = pinocchio::skew(r);
      frame_point_rows(frame_jacobian_, drift, omega, r, terms.point_jacobian.middleRows<3>(3 * i),
                       terms.point_drift.segment<3>(3 * i));
    }
  }
}

void DynamicsCore::compute_in_place(const Eigen::Ref<const Eigen::VectorXd>& q,
                                    const Eigen::Ref<const Eigen::VectorXd>& v) {
  check_sizes(q, v);
  std::lock_guard<std::mutex> lock(*mutex_);
  run_pinocchio(q, v);
  pinocchio::computeCentroidalMomentumTimeVariation(*model_, data_, q, v, zero_acceleration_);
  pinocchio::updateFramePlacements(*model_, data_);
  for (const ContactSpec& contact : contacts_) {
    frame_jacobian_.setZero();
    pinocchio::getFrameJacobian(*model_, data_, contact.frame_id, kWorldAligned, frame_jacobian_);
  }
}

}  // namespace poise
