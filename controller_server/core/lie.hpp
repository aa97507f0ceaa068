// SO(3) and SE_{2+K}(3) maps of the contact-aided invariant EKF, as estimation/lie.py.
//
// An element of SE_{2+K}(3) (Hartley, Ghaffari, Eustice, Grizzle, "Contact-aided invariant
// extended Kalman filtering for robot state estimation", IJRR 39(4), 2020, arXiv:1904.09251,
// the state as a matrix Lie group) is a rotation R with 2 + K vectors x_i (velocity,
// position, contact points). Its tangent vector is ξ = [ξ_R, ξ_1, …] and
//   exp(ξ) = (Γ₀(ξ_R), Γ₁(ξ_R) ξ_1, …, Γ₁(ξ_R) ξ_{2+K}),
// with Γ_m(φ) = Σ_n (φ×)ⁿ / (n + m)! (their Γ functions): Γ₀ is the SO(3) exponential, Γ₁
// its left Jacobian. The coefficients are those of lie.py, evaluated in the same order.
#pragma once

#include <cmath>

#include <Eigen/Core>

namespace poise::lie {

// Below this angle (rad) the Γ coefficients use their Taylor series (5 terms: error < 1e-17).
inline constexpr double kSmallAngle = 0.1;

// (−1)ⁿ / (2n + k)! for k, n in 0 … 4: the coefficients of c_k below (lie._SERIES). Each
// factorial is exact in a double and the division rounded once, as Python's int / int.
inline constexpr double series_coefficient(int k, int n) {
  double factorial = 1.0;
  for (int i = 2; i <= 2 * n + k; ++i) factorial *= i;
  return (n % 2 == 0 ? 1.0 : -1.0) / factorial;
}

// c_k(θ) = Σ_{n=0}^{4} (−θ²)ⁿ / (2n + k)!, Horner in θ², as lie._even_series.
inline double even_series(double theta_squared, int first) {
  static constexpr double kSeries[5][5] = {
      {series_coefficient(0, 0), series_coefficient(0, 1), series_coefficient(0, 2),
       series_coefficient(0, 3), series_coefficient(0, 4)},
      {series_coefficient(1, 0), series_coefficient(1, 1), series_coefficient(1, 2),
       series_coefficient(1, 3), series_coefficient(1, 4)},
      {series_coefficient(2, 0), series_coefficient(2, 1), series_coefficient(2, 2),
       series_coefficient(2, 3), series_coefficient(2, 4)},
      {series_coefficient(3, 0), series_coefficient(3, 1), series_coefficient(3, 2),
       series_coefficient(3, 3), series_coefficient(3, 4)},
      {series_coefficient(4, 0), series_coefficient(4, 1), series_coefficient(4, 2),
       series_coefficient(4, 3), series_coefficient(4, 4)},
  };
  const double* a = kSeries[first];
  const double t2 = theta_squared;
  return a[0] + t2 * (a[1] + t2 * (a[2] + t2 * (a[3] + t2 * a[4])));
}

// c_1 … c_4 of the Γ series: Γ_m = I/m! + c_{m+1} φ× + c_{m+2} φ×² (lie._gamma_coefficients).
struct GammaCoefficients {
  double c1, c2, c3, c4;
};

inline GammaCoefficients gamma_coefficients(const Eigen::Vector3d& phi) {
  const double x = phi.x(), y = phi.y(), z = phi.z();
  const double t2 = x * x + y * y + z * z;
  if (t2 < kSmallAngle * kSmallAngle) {
    // The closed forms cancel catastrophically at small angles.
    return {even_series(t2, 1), even_series(t2, 2), even_series(t2, 3), even_series(t2, 4)};
  }
  const double theta = std::sqrt(t2);
  const double sin = std::sin(theta), cos = std::cos(theta);
  return {sin / theta, (1.0 - cos) / t2, (theta - sin) / (t2 * theta),
          (t2 + 2.0 * cos - 2.0) / (2.0 * t2 * t2)};
}

// [v]×, with [v]× w = v × w (math/spatial.skew).
inline Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return m;
}

// (Γ₀(φ), Γ₁(φ), Γ₂(φ)) at once (lie.so3_gammas):
//   Γ₀ = I + sin θ/θ φ× + (1 − cos θ)/θ² φ×²,
//   Γ₁ = I + (1 − cos θ)/θ² φ× + (θ − sin θ)/θ³ φ×²,
//   Γ₂ = ½ I + (θ − sin θ)/θ³ φ× + (θ² + 2 cos θ − 2)/(2 θ⁴) φ×².
struct Gammas {
  Eigen::Matrix3d gamma0, gamma1, gamma2;
};

inline Gammas so3_gammas(const Eigen::Vector3d& phi) {
  const GammaCoefficients c = gamma_coefficients(phi);
  const Eigen::Matrix3d phi_x = skew(phi);
  const Eigen::Matrix3d phi_x2 = phi_x * phi_x;
  const Eigen::Matrix3d identity = Eigen::Matrix3d::Identity();
  return {identity + c.c1 * phi_x + c.c2 * phi_x2, identity + c.c2 * phi_x + c.c3 * phi_x2,
          0.5 * identity + c.c3 * phi_x + c.c4 * phi_x2};
}

// The rotation exp([φ]×) = Γ₀(φ) (Rodrigues; lie.so3_exp).
inline Eigen::Matrix3d so3_exp(const Eigen::Vector3d& phi) {
  const GammaCoefficients c = gamma_coefficients(phi);
  const Eigen::Matrix3d phi_x = skew(phi);
  return Eigen::Matrix3d::Identity() + c.c1 * phi_x + c.c2 * (phi_x * phi_x);
}

}  // namespace poise::lie
