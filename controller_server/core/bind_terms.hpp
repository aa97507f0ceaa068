// Python's DynamicsTerms into C++'s Terms, for the bindings that test one step of the
// compiled tick against its Python specification on the same terms.
#pragma once

#include <vector>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>

#include "terms.hpp"

namespace poise {

// A copy of `terms` (a controller_server.dynamics.DynamicsTerms). GIL held.
inline Terms terms_from_python(nanobind::handle terms) {
  namespace nb = nanobind;
  using Matrix = Eigen::MatrixXd;
  const auto matrix = [](nb::handle h) { return nb::cast<Matrix>(h); };
  const nb::object point_jacobians = terms.attr("point_jacobians");
  std::vector<Eigen::Index> counts;
  for (nb::handle J : point_jacobians) counts.push_back(matrix(J).rows() / 3);
  const Matrix M = matrix(terms.attr("mass_matrix"));
  Terms out(M.rows(), counts);
  out.mass_matrix = M;
  out.bias_forces = nb::cast<Eigen::VectorXd>(terms.attr("bias_forces"));
  out.position_com_in_world = nb::cast<Eigen::VectorXd>(terms.attr("position_com_in_world"));
  out.total_mass = nb::cast<double>(terms.attr("total_mass"));
  out.position_contact_frames_in_world =
      matrix(terms.attr("position_contact_frames_in_world"));
  const auto tuple_item = [&](const char* name, std::size_t c) {
    return nb::borrow(nb::tuple(terms.attr(name))[c]);
  };
  for (std::size_t c = 0; c < counts.size(); ++c) {
    ContactTerms& contact = out.contacts[c];
    contact.support_jacobian = matrix(tuple_item("support_jacobians", c));
    contact.support_drift = nb::cast<Eigen::VectorXd>(tuple_item("support_drifts", c));
    contact.point_jacobian = matrix(tuple_item("point_jacobians", c));
    contact.point_drift = nb::cast<Eigen::VectorXd>(tuple_item("point_drifts", c));
    contact.point_wrench_map = matrix(tuple_item("point_wrench_maps", c));
    contact.position_points_in_world = matrix(tuple_item("position_points_in_world", c));
  }
  const nb::object momentum = terms.attr("momentum");
  out.R = matrix(momentum.attr("R"));
  out.S = matrix(momentum.attr("S"));
  out.r_bias = nb::cast<Eigen::VectorXd>(momentum.attr("r_bias"));
  out.s_bias = nb::cast<Eigen::VectorXd>(momentum.attr("s_bias"));
  out.linear_momentum = nb::cast<Eigen::VectorXd>(momentum.attr("linear_momentum"));
  out.angular_momentum = nb::cast<Eigen::VectorXd>(momentum.attr("angular_momentum"));
  return out;
}

}  // namespace poise
