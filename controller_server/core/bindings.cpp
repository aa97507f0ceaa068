// nanobind module controller_server._core: DynamicsCore for Python.
//
// Core.compute returns fresh numpy arrays (C order, writable, float64) like
// dynamics.compute_dynamics_terms: they are allocated with NumPy's C API while
// the GIL is held, then filled in place by C++ with the GIL released — no copy,
// and nothing returned aliases the Core. (Returning Eigen objects through
// nanobind's casters works too but cost ~1 µs per array: see REPORT.md.)
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include <nanobind/eigen/dense.h>
#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>

#include <pinocchio/config.hpp>

#include "bind_parts.hpp"
#include "bind_terms.hpp"
#include "dynamics_core.hpp"

namespace nb = nanobind;
using namespace nb::literals;

namespace {

using poise::ContactOut;
using poise::ContactSpec;
using poise::DynamicsCore;
using poise::Points;
using poise::TermsOut;
using VectorRef = Eigen::Ref<const Eigen::VectorXd>;

// A new C-ordered float64 numpy array (GIL held) and its data pointer.
struct NewArray {
  nb::object array;
  double* data;
};

NewArray new_array(std::initializer_list<Eigen::Index> shape) {
  npy_intp dims[2] = {0, 0};
  int ndim = 0;
  for (Eigen::Index extent : shape) dims[ndim++] = static_cast<npy_intp>(extent);
  PyObject* array = PyArray_SimpleNew(ndim, dims, NPY_DOUBLE);
  if (array == nullptr) throw nb::python_error();
  return {nb::steal(array), static_cast<double*>(PyArray_DATA(reinterpret_cast<PyArrayObject*>(array)))};
}

// The arrays of one call, and the Eigen maps over them that DynamicsCore writes.
struct Outputs {
  nb::dict arrays;
  TermsOut maps;
};

Outputs allocate_outputs(const DynamicsCore& core) {
  const Eigen::Index nv = core.model().nv;
  const auto contact_count = static_cast<Eigen::Index>(core.contacts().size());
  nb::dict d;
  auto add = [&d](const char* name, std::initializer_list<Eigen::Index> shape) {
    NewArray a = new_array(shape);
    d[name] = a.array;
    return a.data;
  };
  TermsOut maps{
      poise::RowMatrixMap(add("mass_matrix", {nv, nv}), nv, nv),
      poise::VectorMap(add("bias_forces", {nv}), nv),
      poise::Vector3Map(add("position_com_in_world", {3})),
      0.0,
      {},
      poise::PointsMap(add("position_contact_frames_in_world", {contact_count, 3}), contact_count, 3),
      poise::RowMatrixMap(add("R", {3, nv}), 3, nv),
      poise::RowMatrixMap(add("S", {3, nv}), 3, nv),
      poise::Vector3Map(add("r_bias", {3})),
      poise::Vector3Map(add("s_bias", {3})),
      poise::Vector3Map(add("linear_momentum", {3})),
      poise::Vector3Map(add("angular_momentum", {3})),
  };

  nb::list support_jacobians, support_drifts, point_jacobians, point_drifts, wrench_maps, points;
  auto append = [](nb::list& list, std::initializer_list<Eigen::Index> shape) {
    NewArray a = new_array(shape);
    list.append(a.array);
    return a.data;
  };
  maps.contacts.reserve(core.contacts().size());
  for (const ContactSpec& contact : core.contacts()) {
    const Eigen::Index k = contact.points_in_frame.rows();
    maps.contacts.push_back(ContactOut{
        poise::RowMatrixMap(append(support_jacobians, {6, nv}), 6, nv),
        poise::VectorMap(append(support_drifts, {6}), 6),
        poise::RowMatrixMap(append(point_jacobians, {3 * k, nv}), 3 * k, nv),
        poise::VectorMap(append(point_drifts, {3 * k}), 3 * k),
        poise::RowMatrixMap(append(wrench_maps, {6, 3 * k}), 6, 3 * k),
        poise::PointsMap(append(points, {k, 3}), k, 3),
    });
  }
  d["support_jacobians"] = support_jacobians;
  d["support_drifts"] = support_drifts;
  d["point_jacobians"] = point_jacobians;
  d["point_drifts"] = point_drifts;
  d["point_wrench_maps"] = wrench_maps;
  d["position_points_in_world"] = points;
  return {std::move(d), std::move(maps)};
}

// Core.compute: every term of dynamics.compute_dynamics_terms at (q, v).
nb::dict compute(DynamicsCore& core, VectorRef q, VectorRef v) {
  core.check_sizes(q, v);  // before allocating (raises ValueError)
  Outputs out = allocate_outputs(core);
  {
    nb::gil_scoped_release release;
    core.compute(q, v, out.maps);
  }
  out.arrays["total_mass"] = nb::float_(out.maps.total_mass);
  return out.arrays;
}

DynamicsCore make_core(const std::string& model_text, const std::vector<std::size_t>& frame_ids,
                       const std::vector<Points>& points_per_contact) {
  if (frame_ids.size() != points_per_contact.size()) {
    throw std::invalid_argument("one (k, 3) points array per contact frame id is needed");
  }
  std::vector<ContactSpec> contacts;
  for (std::size_t c = 0; c < frame_ids.size(); ++c) {
    contacts.push_back({static_cast<pinocchio::FrameIndex>(frame_ids[c]), points_per_contact[c]});
  }
  std::shared_ptr<const poise::Model> model;
  {
    nb::gil_scoped_release release;  // parsing ~50 kB of text: let other threads run
    model = poise::model_from_string(model_text);
  }
  return DynamicsCore(std::move(model), std::move(contacts));
}

}  // namespace

NB_MODULE(_core, m) {
  if (_import_array() < 0) throw nb::python_error();  // NumPy's C API table
  m.doc() = "Compiled rigid-body terms for controller_server.dynamics (Pinocchio, C++).";
  // The Pinocchio this module was compiled against: its Model layout and
  // serialization must match the `pin` that Python imports (checked by callers).
  m.attr("PINOCCHIO_VERSION") = PINOCCHIO_VERSION;

  nb::class_<DynamicsCore>(m, "Core",
                           "One robot model (shared, read only) and one session's workspace.")
      .def(
          "__init__",
          [](DynamicsCore* self, const std::string& model_text,
             const std::vector<std::size_t>& frame_ids,
             const std::vector<Points>& points_per_contact) {
            new (self) DynamicsCore(make_core(model_text, frame_ids, points_per_contact));
          },
          "model_text"_a, "frame_ids"_a, "points_per_contact"_a,
          "From `pin.Model.saveToString()`, the contact frame ids and each contact's "
          "(k, 3) points in its frame.")
      .def("compute", &compute, "q"_a, "v"_a,
           "Every term of dynamics.compute_dynamics_terms at (q, v): a dict of new arrays "
           "(DynamicsTerms / MomentumRates field names; per-contact fields are lists).")
      .def("compute_in_place", &DynamicsCore::compute_in_place, "q"_a, "v"_a,
           nb::call_guard<nb::gil_scoped_release>(),
           "The Pinocchio calls of compute() only, returning nothing (for timing).")
      .def("clone", &DynamicsCore::clone,
           "A new workspace (pinocchio Data) on the same shared model: one per session.")
      .def_prop_ro("nq", [](const DynamicsCore& core) { return core.model().nq; })
      .def_prop_ro("nv", [](const DynamicsCore& core) { return core.model().nv; })
      .def_prop_ro("nframes", [](const DynamicsCore& core) { return core.model().nframes; })
      .def_prop_ro("contact_frame_ids", [](const DynamicsCore& core) {
        std::vector<std::size_t> ids;
        for (const ContactSpec& contact : core.contacts()) ids.push_back(contact.frame_id);
        return ids;
      });

  // The compiled tick's steps, one binding file each (bind_parts.hpp).
  poise::bind_parts(m);
}
