// The readers and printers of the config keys whose syntax is not their type's plain JSON
// (config_keys.cpp names them in the keys' rows; config.cpp defines them).
#pragma once

#include "bodyd/daemon/config.h"

#include <nlohmann/json_fwd.hpp>

#include <string>

namespace bodyd::daemon {

// "sources": an array of spec strings.
std::string read_sources(const nlohmann::json& value, const std::string& where, DaemonConfig& config);
// "outputs": spec strings or objects {"type": SCHEME, "target": TARGET, KEY: VALUE...}.
std::string read_outputs(const nlohmann::json& value, const std::string& where, DaemonConfig& config);
// "offsets": {"ROLE": {"position_m": [x,y,z], "rotation_xyzw": [x,y,z,w]}, ...}.
std::string read_offsets(const nlohmann::json& value, const std::string& where, DaemonConfig& config);
nlohmann::json print_offsets(const DaemonConfig& config);

}  // namespace bodyd::daemon
