#pragma once
// Operations that derive objects from others, with every parameter recorded so that an expert
// can reprocess later: each operation has a JSON parameter set with every default written out;
// reprocessing re-runs it with some parameters changed and stores a new version beside the old.
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "artisan/worldmodel/workspace.hpp"

namespace artisan::worldmodel {

/// Names of the registered operations (e.g. "mesh").
std::vector<std::string> operation_names();

/// The full parameter set of an operation with its defaults. Throws for an unknown operation.
nlohmann::json default_parameters(const std::string& operation);

/// `base` with `overrides` applied. Every override key must exist in `base` and keep its JSON
/// type (a number stays a number; a null may become an array and back); throws artisan::Error
/// naming the key, the value and the valid keys otherwise.
nlohmann::json apply_overrides(const nlohmann::json& base, const nlohmann::json& overrides, const std::string& operation);

/// "key=value" settings (the command line's --set) as a JSON object; a value that parses as
/// JSON (25, true, null, [1,2]) is taken as such, anything else as a string.
nlohmann::json parse_settings(const std::vector<std::string>& settings);

/// Runs `operation` on `inputs` with `overrides` on its defaults and stores the result as
/// `name` in `folder`, with provenance, in one transaction. Returns the new object.
ObjectId run_operation(Workspace& workspace, const std::string& operation, const std::vector<ObjectId>& inputs,
                       const nlohmann::json& overrides, ObjectId folder, const std::string& name);

/// Re-runs the operation that made `id` on the same inputs with its recorded parameters and
/// `overrides`, storing the result as the next version. Throws for objects that were not
/// derived (imports, folders).
ObjectId reprocess(Workspace& workspace, ObjectId id, const nlohmann::json& overrides);

}  // namespace artisan::worldmodel
