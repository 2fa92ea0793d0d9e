#pragma once
// Overriding a parameter struct's fields by name (from a workcell's sensor "params").
#include <cmath>
#include <map>
#include <string>
#include <variant>
#include <vector>

#include "artisan/core/error.hpp"

namespace artisan::sim {

using FieldRef = std::variant<double*, int*>;

inline void apply_overrides(const std::string& model, const std::map<std::string, double>& overrides,
                            const std::vector<std::pair<std::string, FieldRef>>& fields) {
  for (const auto& [name, value] : overrides) {
    bool found = false;
    std::string known;
    for (const auto& [fname, ref] : fields) {
      known += (known.empty() ? "" : ", ") + fname;
      if (fname != name) continue;
      found = true;
      if (!std::isfinite(value)) throw Error(model + " parameter '" + name + "' is not finite");
      if (auto* d = std::get_if<double*>(&ref)) {
        **d = value;
      } else {
        if (value != std::round(value)) throw Error(model + " parameter '" + name + "' must be an integer, got " + std::to_string(value));
        *std::get<int*>(ref) = static_cast<int>(value);
      }
    }
    if (!found) throw Error(model + ": unknown parameter '" + name + "' (known: " + known + ")");
  }
}

}  // namespace artisan::sim
