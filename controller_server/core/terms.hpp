// The dynamics terms of one tick, owned by C++ (controller_server.dynamics.DynamicsTerms).
//
// DynamicsCore writes them through TermsOut's maps; the compiled tick's steps (objectives,
// KKT, inverse dynamics) read them as plain Eigen matrices. Allocated once per session
// (sizes: nv and each contact's point count), rewritten in place every tick.
#pragma once

#include <cstddef>
#include <vector>

#include <Eigen/Core>

#include "dynamics_core.hpp"

namespace poise {

// One contact's rows: field names of DynamicsTerms (one entry of each per-contact tuple).
struct ContactTerms {
  RowMatrix support_jacobian;        // (6, nv): [v_origin; ω] of the frame, world axes
  Eigen::VectorXd support_drift;     // (6,): J̇ q̇
  RowMatrix point_jacobian;          // (3k, nv)
  Eigen::VectorXd point_drift;       // (3k,)
  RowMatrix point_wrench_map;        // (6, 3k)
  Points position_points_in_world;   // (k, 3)
};

struct Terms {
  RowMatrix mass_matrix;                     // (nv, nv), symmetric
  Eigen::VectorXd bias_forces;               // (nv,)
  Eigen::Vector3d position_com_in_world;
  double total_mass = 0.0;                   // kg
  std::vector<ContactTerms> contacts;        // in contact order
  Points position_contact_frames_in_world;   // (contacts, 3)
  RowMatrix R;                               // (3, nv): linear rows of A_g
  RowMatrix S;                               // (3, nv): angular rows of A_g (about the CoM)
  Eigen::Vector3d r_bias, s_bias;            // momentum rates at q̈ = 0
  Eigen::Vector3d linear_momentum, angular_momentum;

  // Storage for nv DoFs and contacts with `point_counts[c]` sole points each.
  Terms(Eigen::Index nv, const std::vector<Eigen::Index>& point_counts)
      : mass_matrix(RowMatrix::Zero(nv, nv)),
        bias_forces(Eigen::VectorXd::Zero(nv)),
        position_com_in_world(Eigen::Vector3d::Zero()),
        position_contact_frames_in_world(Points::Zero(static_cast<Eigen::Index>(point_counts.size()), 3)),
        R(RowMatrix::Zero(3, nv)),
        S(RowMatrix::Zero(3, nv)),
        r_bias(Eigen::Vector3d::Zero()),
        s_bias(Eigen::Vector3d::Zero()),
        linear_momentum(Eigen::Vector3d::Zero()),
        angular_momentum(Eigen::Vector3d::Zero()) {
    for (Eigen::Index k : point_counts) {
      contacts.push_back({RowMatrix::Zero(6, nv), Eigen::VectorXd::Zero(6),
                          RowMatrix::Zero(3 * k, nv), Eigen::VectorXd::Zero(3 * k),
                          RowMatrix::Zero(6, 3 * k), Points::Zero(k, 3)});
    }
  }

  Eigen::Index nv() const { return bias_forces.size(); }

  // Maps over this storage, for DynamicsCore::compute (valid while *this lives unmoved).
  TermsOut maps() {
    const Eigen::Index nv = this->nv();
    TermsOut out{RowMatrixMap(mass_matrix.data(), nv, nv),
                 VectorMap(bias_forces.data(), nv),
                 Vector3Map(position_com_in_world.data()),
                 0.0,
                 {},
                 PointsMap(position_contact_frames_in_world.data(),
                           position_contact_frames_in_world.rows(), 3),
                 RowMatrixMap(R.data(), 3, nv),
                 RowMatrixMap(S.data(), 3, nv),
                 Vector3Map(r_bias.data()),
                 Vector3Map(s_bias.data()),
                 Vector3Map(linear_momentum.data()),
                 Vector3Map(angular_momentum.data())};
    out.contacts.reserve(contacts.size());
    for (ContactTerms& c : contacts) {
      const Eigen::Index k = c.position_points_in_world.rows();
      out.contacts.push_back({RowMatrixMap(c.support_jacobian.data(), 6, nv),
                              VectorMap(c.support_drift.data(), 6),
                              RowMatrixMap(c.point_jacobian.data(), 3 * k, nv),
                              VectorMap(c.point_drift.data(), 3 * k),
                              RowMatrixMap(c.point_wrench_map.data(), 6, 3 * k),
                              PointsMap(c.position_points_in_world.data(), k, 3)});
    }
    return out;
  }
};

}  // namespace poise
