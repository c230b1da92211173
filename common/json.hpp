// JSON summaries: nlohmann::json with keys kept in insertion order, written with two-space
// indentation and a final newline. NaN and infinities become null.
#pragma once

#include <nlohmann/json.hpp>

#include <string>

namespace neurosim::common {

using Json = nlohmann::ordered_json;

std::string to_text(const Json& j);
// Writes to_text(j) to file; throws std::runtime_error naming the file when it cannot.
void write_json(const std::string& file, const Json& j);

}  // namespace neurosim::common
