// Ground reference points and the support polygon (controller_server/balance_points.py).
//
// Flat ground at height h with normal +z. The same arithmetic as the Python, in the same
// order, on polygons of a handful of vertices held in vectors whose capacity is reserved
// once (Polygon::reserve): no allocation per tick once the largest polygon has been seen.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "dynamics_core.hpp"

namespace poise {

// Counter-clockwise x–y vertices (a segment, a point, or empty).
using Polygon = std::vector<Eigen::Vector2d>;

// Scratch space of the polygon functions (kept by the caller: capacity survives ticks).
struct PolygonScratch {
  Polygon sorted;
  Polygon vertices;
  std::vector<Eigen::Vector3d> lines;
};

// Convex hull of the points' x–y (Andrew's monotone chain, collinear vertices dropped):
// balance_points.support_polygon.
void support_polygon(const Eigen::Ref<const Points>& points_in_world, PolygonScratch& scratch,
                     Polygon& hull);

// balance_points.admissible_cop_polygon: the polygon shrunk by min(margin, 1/4 its width).
void admissible_cop_polygon(const Polygon& polygon, double margin, PolygonScratch& scratch,
                            Polygon& shrunk);

// balance_points.closest_point_in_polygon (NaN for an empty or non-finite polygon).
Eigen::Vector2d closest_point_in_polygon(const Eigen::Vector2d& point, const Polygon& polygon);

// balance_points.ground_reference_points: COP (eq. 3.3–3.6) and CMP (eq. 3.9–3.10) of the
// contacts' ground wrenches (rows [f; τ about the frame origin]); NaN without normal force.
void ground_reference_points(const Eigen::Ref<const Points>& position_contact_frames_in_world,
                             const Eigen::Vector3d& position_com_in_world,
                             const Eigen::Ref<const RowMatrix>& contact_wrench_in_world,
                             const std::vector<bool>& supports, double ground_height,
                             Eigen::Vector3d& center_of_pressure,
                             Eigen::Vector3d& centroidal_moment_pivot);

}  // namespace poise
