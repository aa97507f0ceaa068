// The compiled tick's steps, each bound in its own bind_<step>.cpp so that a step, its
// bindings and its agreement test change together. NB_MODULE (bindings.cpp) calls
// bind_parts once; add a step by declaring its bind_<step> here and calling it below.
#pragma once

#include <nanobind/nanobind.h>

namespace poise {

// Each binds its step's functions and classes into `m` (controller_server._core).
void bind_estimator(nanobind::module_& m);         // bind_estimator.cpp: the IMU path's filter
void bind_inverse_dynamics(nanobind::module_& m);  // bind_inverse_dynamics.cpp
void bind_joint_limits(nanobind::module_& m);      // bind_joint_limits.cpp
void bind_weighted(nanobind::module_& m);          // bind_weighted.cpp

inline void bind_parts(nanobind::module_& m) {
  bind_estimator(m);
  bind_inverse_dynamics(m);
  bind_joint_limits(m);
  bind_weighted(m);
}

}  // namespace poise
