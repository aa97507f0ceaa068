// Model transfer from Python: pin.Model is a Boost.Python object, not a nanobind
// one, so it crosses as the text of Pinocchio's own serialization
// (pin.Model.saveToString() on the Python side, loadFromString here): an exact
// copy (doubles are written with 17 significant digits). Kept in its own
// translation unit: Boost.Serialization is the slowest header set to compile.
#include <memory>
#include <string>

#include <pinocchio/serialization.hpp>

#include "dynamics_core.hpp"

namespace poise {

std::shared_ptr<const Model> model_from_string(const std::string& text) {
  auto model = std::make_shared<Model>();
  model->loadFromString(text);  // Boost text archive; throws on malformed text
  return model;
}

}  // namespace poise
