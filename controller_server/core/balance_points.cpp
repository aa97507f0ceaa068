#include "balance_points.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace poise {

namespace {

constexpr double kMinNormalForceN = 1e-6;   // MIN_NORMAL_FORCE_N
constexpr double kCollinearSine = 1e-9;     // COLLINEAR_SINE
constexpr double kMaxMarginFraction = 0.25; // MAX_MARGIN_FRACTION
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

bool lexicographic(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
}

// One chain of the monotone-chain hull over `ordered` (reversed: the upper chain), appended
// to `hull`: a vertex stays on any strictly left turn, however small (support_polygon).
void chain(const Polygon& ordered, bool reversed, Polygon& hull) {
  const std::size_t start = hull.size();
  const std::size_t n = ordered.size();
  for (std::size_t k = 0; k < n; ++k) {
    const Eigen::Vector2d& b = ordered[reversed ? n - 1 - k : k];
    while (hull.size() - start >= 2) {
      const Eigen::Vector2d& o = hull[hull.size() - 2];
      const Eigen::Vector2d& a = hull[hull.size() - 1];
      if ((a.x() - o.x()) * (b.y() - o.y()) - (a.y() - o.y()) * (b.x() - o.x()) > 0.0) break;
      hull.pop_back();
    }
    hull.push_back(b);
  }
}

// Drops, one at a time until none is left, a vertex v_i for which
// drop(v_i − v_{i−1}, v_{i+1} − v_i) holds (the loop of _corners and _turning_vertices).
template <typename Drop>
void drop_vertices(Polygon& vertices, Drop drop) {
  bool removed = true;
  while (removed && vertices.size() >= 3) {
    removed = false;
    const std::size_t n = vertices.size();
    for (std::size_t i = 0; i < n; ++i) {
      const Eigen::Vector2d before = vertices[i] - vertices[(i + n - 1) % n];
      const Eigen::Vector2d after = vertices[(i + 1) % n] - vertices[i];
      if (drop(before.x(), before.y(), after.x(), after.y())) {
        vertices.erase(vertices.begin() + static_cast<std::ptrdiff_t>(i));
        removed = true;
        break;
      }
    }
  }
}

// balance_points._corners, in place: drop the vertices whose edges turn by less than
// COLLINEAR_SINE and that lie between their neighbours (not where the boundary turns back).
void corners(Polygon& vertices) {
  drop_vertices(vertices, [](double bx, double by, double ax, double ay) {
    const bool forward = bx * ax + by * ay > 0.0;
    return forward &&
           std::abs(bx * ay - by * ax) <= kCollinearSine * std::hypot(bx, by) * std::hypot(ax, ay);
  });
}

// balance_points._turning_vertices, in place: drop the vertices where the closed polygon
// does not turn left by more than round-off.
void turning_vertices(Polygon& vertices) {
  drop_vertices(vertices, [](double bx, double by, double ax, double ay) {
    return !(bx * ay - by * ax > kCollinearSine * std::hypot(bx, by) * std::hypot(ax, ay));
  });
}

// balance_points.polygon_width of the turning vertices `vertices`.
double polygon_width(const Polygon& vertices) {
  if (vertices.size() < 3) return 0.0;
  double width = std::numeric_limits<double>::infinity();
  const std::size_t n = vertices.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d& v0 = vertices[i];
    const Eigen::Vector2d& v1 = vertices[(i + 1) % n];
    const double length = std::hypot(v1.x() - v0.x(), v1.y() - v0.y());
    const double nx = (v0.y() - v1.y()) / length, ny = (v1.x() - v0.x()) / length;
    double extent = -std::numeric_limits<double>::infinity();
    for (const Eigen::Vector2d& v : vertices) {
      extent = std::max(extent, nx * (v.x() - v0.x()) + ny * (v.y() - v0.y()));
    }
    width = std::min(width, extent);
  }
  return width;
}

}  // namespace

void support_polygon(const Eigen::Ref<const Points>& points_in_world, PolygonScratch& work,
                     Polygon& hull) {
  Polygon& scratch = work.sorted;
  scratch.clear();
  hull.clear();
  for (Eigen::Index i = 0; i < points_in_world.rows(); ++i) {
    scratch.emplace_back(points_in_world(i, 0), points_in_world(i, 1));
  }
  std::sort(scratch.begin(), scratch.end(), lexicographic);
  scratch.erase(std::unique(scratch.begin(), scratch.end(),
                            [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
                              return a.x() == b.x() && a.y() == b.y();
                            }),
                scratch.end());
  if (scratch.size() <= 2) {
    hull = scratch;
    return;
  }
  chain(scratch, false, hull);  // lower
  hull.pop_back();
  chain(scratch, true, hull);   // upper, appended after the lower chain
  hull.pop_back();
  corners(hull);
}

void admissible_cop_polygon(const Polygon& polygon, double margin, PolygonScratch& scratch,
                            Polygon& shrunk) {
  shrunk.clear();
  if (polygon.empty()) {
    shrunk.emplace_back(0.0, 0.0);
    return;
  }
  Polygon& vertices = scratch.vertices;
  vertices = polygon;
  turning_vertices(vertices);
  margin = std::min(margin, kMaxMarginFraction * polygon_width(vertices));
  // shrink_polygon: the vertex mean of the polygon as given is the collapsed answer.
  Eigen::Vector2d centre(0.0, 0.0);
  double sx = 0.0, sy = 0.0;
  for (const Eigen::Vector2d& v : polygon) sx += v.x();
  for (const Eigen::Vector2d& v : polygon) sy += v.y();
  centre << sx / static_cast<double>(polygon.size()), sy / static_cast<double>(polygon.size());
  if (vertices.size() < 3) {
    shrunk.push_back(centre);
    return;
  }
  if (margin <= 0.0) {
    shrunk = vertices;
    return;
  }
  // Offset edge i (vertex i to i + 1): n_i · p = o_i, n_i its outward unit normal.
  const std::size_t n = vertices.size();
  std::vector<Eigen::Vector3d>& line = scratch.lines;
  line.clear();
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d& v0 = vertices[i];
    const Eigen::Vector2d& v1 = vertices[(i + 1) % n];
    const double length = std::hypot(v1.x() - v0.x(), v1.y() - v0.y());
    const double nx = (v1.y() - v0.y()) / length, ny = (v0.x() - v1.x()) / length;
    line.emplace_back(nx, ny, nx * v0.x() + ny * v0.y() - margin);
  }
  // Vertex i: where the offset edges i − 1 and i meet (Cramer's rule).
  const double limit = margin * (1.0 - 1e-9);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d& a = line[(i + n - 1) % n];
    const Eigen::Vector3d& b = line[i];
    const double determinant = a[0] * b[1] - a[1] * b[0];
    const double x = (a[2] * b[1] - a[1] * b[2]) / determinant;
    const double y = (a[0] * b[2] - a[2] * b[0]) / determinant;
    // Too much margin turns the offset polygon inside out.
    bool inside_out = !(std::isfinite(x) && std::isfinite(y));
    for (std::size_t j = 0; j < n && !inside_out; ++j) {
      if (line[j][2] + margin - (line[j][0] * x + line[j][1] * y) < limit) inside_out = true;
    }
    if (inside_out) {
      shrunk.clear();
      shrunk.push_back(centre);
      return;
    }
    shrunk.emplace_back(x, y);
  }
}

Eigen::Vector2d closest_point_in_polygon(const Eigen::Vector2d& point, const Polygon& polygon) {
  const double px = point.x(), py = point.y();
  if (polygon.empty()) return Eigen::Vector2d(kNaN, kNaN);
  for (const Eigen::Vector2d& v : polygon) {
    if (!(std::isfinite(v.x()) && std::isfinite(v.y()))) return Eigen::Vector2d(kNaN, kNaN);
  }
  const std::size_t n = polygon.size();
  if (n >= 3) {
    bool inside = true;
    for (std::size_t i = 0; i < n && inside; ++i) {
      const Eigen::Vector2d& v0 = polygon[i];
      const Eigen::Vector2d& v1 = polygon[(i + 1) % n];
      inside = (v1.x() - v0.x()) * (py - v0.y()) - (v1.y() - v0.y()) * (px - v0.x()) >= 0.0;
    }
    if (inside) return point;
  }
  Eigen::Vector2d best(px, py);
  double best_distance = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d& v0 = polygon[i];
    const Eigen::Vector2d& v1 = polygon[(i + 1) % n];
    const double sx = v1.x() - v0.x(), sy = v1.y() - v0.y();
    double fraction = ((px - v0.x()) * sx + (py - v0.y()) * sy) / std::max(sx * sx + sy * sy, 1e-300);
    fraction = std::min(std::max(fraction, 0.0), 1.0);
    const double cx = v0.x() + fraction * sx, cy = v0.y() + fraction * sy;
    const double distance = std::hypot(cx - px, cy - py);
    if (distance < best_distance) {
      best << cx, cy;
      best_distance = distance;
    }
  }
  return best;
}

void ground_reference_points(const Eigen::Ref<const Points>& origins,
                             const Eigen::Vector3d& position_com_in_world,
                             const Eigen::Ref<const RowMatrix>& wrenches,
                             const std::vector<bool>& supports, double ground_height,
                             Eigen::Vector3d& cop, Eigen::Vector3d& cmp) {
  // The reference: the mean of the supporting frames' origins (all of them if none).
  Eigen::Index chosen = 0;
  for (bool on : supports) chosen += on ? 1 : 0;
  const bool all = chosen == 0;
  double c[3] = {0.0, 0.0, 0.0};
  for (int axis = 0; axis < 3; ++axis) {
    double sum = 0.0;
    for (Eigen::Index i = 0; i < origins.rows(); ++i) {
      if (all || supports[static_cast<std::size_t>(i)]) sum += origins(i, axis);
    }
    c[axis] = sum / static_cast<double>(all ? origins.rows() : chosen);
  }
  double force[3] = {0.0, 0.0, 0.0}, torque[3] = {0.0, 0.0, 0.0};
  for (Eigen::Index i = 0; i < wrenches.rows(); ++i) {
    const double fx = wrenches(i, 0), fy = wrenches(i, 1), fz = wrenches(i, 2);
    const double tx = wrenches(i, 3), ty = wrenches(i, 4), tz = wrenches(i, 5);
    const double rx = origins(i, 0) - c[0], ry = origins(i, 1) - c[1], rz = origins(i, 2) - c[2];
    force[0] += fx;
    force[1] += fy;
    force[2] += fz;
    torque[0] += tx + ry * fz - rz * fy;
    torque[1] += ty + rz * fx - rx * fz;
    torque[2] += tz + rx * fy - ry * fx;
  }
  if (force[2] < kMinNormalForceN) {
    cop.setConstant(kNaN);
    cmp.setConstant(kNaN);
    return;
  }
  const double height = c[2] - ground_height;
  cop << c[0] + -(torque[1] + height * force[0]) / force[2],
      c[1] + (torque[0] - height * force[1]) / force[2], c[2] + -height;
  const double drop = position_com_in_world.z() - ground_height;
  cmp << position_com_in_world.x() - force[0] / force[2] * drop,
      position_com_in_world.y() - force[1] / force[2] * drop, ground_height;
}

}  // namespace poise
