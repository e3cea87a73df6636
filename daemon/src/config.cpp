#include "bodyd/daemon/config.h"

#include "bodyd/daemon/output.h"
#include "bodyd/drivers/open_source.h"
#include "bodyd/motion/limits.h"
#include "bodyd/paths/data_files.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <cctype>
#include <cmath>
#include <limits>
#include <fstream>
#include <iostream>
#include <sstream>


namespace bodyd::daemon {
namespace {

using nlohmann::json;

std::string type_name(const json& j) { return j.type_name(); }

std::string fmt_number(double x) {
  std::ostringstream s;
  s << x;
  return s.str();
}

// Reads one typed value; on a type mismatch, sets `error`.
template <typename T>
bool get_value(const json& j, const std::string& where, T& out, std::string& error) {
  if constexpr (std::is_same_v<T, bool>) {
    if (!j.is_boolean()) {
      error = where + ": expected true or false, got " + type_name(j);
      return false;
    }
  } else if constexpr (std::is_same_v<T, std::string>) {
    if (!j.is_string()) {
      error = where + ": expected a string, got " + type_name(j);
      return false;
    }
  } else if constexpr (std::is_integral_v<T>) {
    if (!j.is_number_integer() || (std::is_unsigned_v<T> && !j.is_number_unsigned())) {
      error = where + ": expected a " + (std::is_unsigned_v<T> ? "non-negative " : "") + "integer, got " +
              (j.is_number() ? j.dump() : type_name(j));
      return false;
    }
    // Range of T, checked before converting (3000000000 into an int would wrap; issue 11).
    const bool fits = j.is_number_unsigned()
                          ? j.get<std::uint64_t>() <= static_cast<std::uint64_t>(std::numeric_limits<T>::max())
                          : j.get<std::int64_t>() >= static_cast<std::int64_t>(std::numeric_limits<T>::min()) &&
                                (std::is_unsigned_v<T> || j.get<std::int64_t>() <= static_cast<std::int64_t>(std::numeric_limits<T>::max()));
    if (!fits) {
      error = where + ": " + j.dump() + " is out of range (" + std::to_string(std::numeric_limits<T>::min()) + " .. " +
              std::to_string(std::numeric_limits<T>::max()) + ")";
      return false;
    }
  } else {
    if (!j.is_number()) {
      error = where + ": expected a number, got " + type_name(j);
      return false;
    }
  }
  out = j.get<T>();
  return true;
}

bool get_vec(const json& j, const std::string& where, std::size_t n, std::vector<double>& out, std::string& error) {
  if (!j.is_array() || j.size() != n) {
    error = where + ": expected an array of " + std::to_string(n) + " numbers";
    return false;
  }
  out.clear();
  for (const auto& v : j) {
    if (!v.is_number()) {
      error = where + ": expected an array of " + std::to_string(n) + " numbers, found " + type_name(v);
      return false;
    }
    out.push_back(v.get<double>());
  }
  return true;
}

std::string offset_from_values(const std::vector<double>& v, const std::string& where, DeviceOffset& out) {
  for (double x : v)
    if (!std::isfinite(x)) return where + ": values must be finite";
  for (int k = 0; k < 3; ++k)
    if (std::fabs(v[static_cast<std::size_t>(k)]) > limits::kMaxAbsOffsetM)
      return where + ": each position coordinate must be within +-" + fmt_number(limits::kMaxAbsOffsetM) +
             " m (an offset from the device to the joint; docs/daemon.md, \"Limits\")";
  out.position_m = Vec3(v[0], v[1], v[2]);
  out.rotation = Quat::Identity();
  if (v.size() == 7) {
    const Quat q(v[6], v[3], v[4], v[5]);  // (w, x, y, z) constructor; input is x, y, z, w
    if (std::abs(q.norm() - 1.0) > 1e-3)
      return where + ": the rotation (x, y, z, w) must be a unit quaternion (norm " + std::to_string(q.norm()) + ")";
    out.rotation = q.normalized();
  }
  return {};
}

std::string apply_offsets(const json& j, const std::string& where, DaemonConfig& config) {
  if (!j.is_object()) return where + ": expected an object with keys head, left_hand, right_hand";
  for (const auto& [key, value] : j.items()) {
    const std::string w = where + "." + key;
    const auto role = role_from_name(key);
    if (!role) return w + ": unknown role (expected head, left_hand or right_hand)";
    if (!value.is_object()) return w + ": expected an object {\"position_m\": [x,y,z], \"rotation_xyzw\": [x,y,z,w]}";
    std::vector<double> values{0, 0, 0};
    std::string error;
    for (const auto& [k, v] : value.items()) {
      if (k == "position_m") {
        std::vector<double> p;
        if (!get_vec(v, w + ".position_m", 3, p, error)) return error;
        values[0] = p[0], values[1] = p[1], values[2] = p[2];
      } else if (k == "rotation_xyzw") {
        std::vector<double> q;
        if (!get_vec(v, w + ".rotation_xyzw", 4, q, error)) return error;
        values.resize(3);
        values.insert(values.end(), q.begin(), q.end());
      } else {
        return w + "." + k + ": unknown key (expected position_m, rotation_xyzw)";
      }
    }
    DeviceOffset offset;
    if (std::string e = offset_from_values(values, w, offset); !e.empty()) return e;
    config.offsets[static_cast<int>(*role)] = offset;
  }
  return {};
}

// "filter": {"enabled": true, "min_cutoff_hz": 1.0, ...}: the diffusion's tracker filter.
// Values are checked by validate_config (validate(OneEuroOptions)).
std::string apply_filter(const json& j, const std::string& where, OneEuroOptions& filter) {
  if (!j.is_object()) return where + ": expected an object like {\"enabled\": true, \"min_cutoff_hz\": 1.0}";
  std::string error;
  for (const auto& [key, value] : j.items()) {
    const std::string w = where + "." + key;
    bool ok = true;
    if (key == "enabled") ok = get_value(value, w, filter.enabled, error);
    else if (key == "min_cutoff_hz") ok = get_value(value, w, filter.min_cutoff_hz, error);
    else if (key == "beta_per_m_s") ok = get_value(value, w, filter.beta_per_m_s, error);
    else if (key == "d_cutoff_hz") ok = get_value(value, w, filter.d_cutoff_hz, error);
    else if (key == "rot_min_cutoff_hz") ok = get_value(value, w, filter.rot_min_cutoff_hz, error);
    else if (key == "rot_beta_per_rad_s") ok = get_value(value, w, filter.rot_beta_per_rad_s, error);
    else
      return w + ": unknown key (expected enabled, min_cutoff_hz, beta_per_m_s, d_cutoff_hz, rot_min_cutoff_hz, "
                 "rot_beta_per_rad_s; docs/daemon.md, \"Tracker filter\")";
    if (!ok) return error;
  }
  return {};
}

std::string apply_sim(const json& j, const std::string& where, SimOptions& sim) {
  if (!j.is_object()) return where + ": expected an object";
  std::string error;
  for (const auto& [key, value] : j.items()) {
    const std::string w = where + "." + key;
    bool ok = true;
    if (key == "rate_hz") ok = get_value(value, w, sim.rate_hz, error);
    else if (key == "head_rate_hz") ok = get_value(value, w, sim.role_rate_hz[0], error);
    else if (key == "left_hand_rate_hz") ok = get_value(value, w, sim.role_rate_hz[1], error);
    else if (key == "right_hand_rate_hz") ok = get_value(value, w, sim.role_rate_hz[2], error);
    else if (key == "position_noise_mm") ok = get_value(value, w, sim.position_noise_mm, error);
    else if (key == "rotation_noise_deg") ok = get_value(value, w, sim.rotation_noise_deg, error);
    else if (key == "latency_ms") ok = get_value(value, w, sim.latency_ms, error);
    else if (key == "jitter_ms") ok = get_value(value, w, sim.jitter_ms, error);
    else if (key == "dropout_rate_hz") ok = get_value(value, w, sim.dropout_rate_hz, error);
    else if (key == "dropout_mean_ms") ok = get_value(value, w, sim.dropout_mean_ms, error);
    else if (key == "seed") ok = get_value(value, w, sim.seed, error);
    else return w + ": unknown key (see docs/daemon.md, \"sim\")";
    if (!ok) return error;
  }
  return {};
}

// "outputs": a list of specs ("vrchat:127.0.0.1:9000?slots=hip,feet") or objects
// {"type": "vrchat", "target": "127.0.0.1:9000", "slots": ["hip", "feet"], "rate": 60}
// (docs/outputs.md). Objects become specs; the output checks its options when it is made.
std::string apply_outputs(const json& j, const std::string& where, DaemonConfig& config) {
  if (!j.is_array()) return where + ": expected an array of output specs (\"vrchat:127.0.0.1:9000\") or objects";
  config.outputs.clear();
  for (std::size_t i = 0; i < j.size(); ++i) {
    const json& item = j[i];
    const std::string w = where + "[" + std::to_string(i) + "]";
    if (item.is_string()) {
      config.outputs.push_back(item.get<std::string>());
      continue;
    }
    if (!item.is_object() || !item.contains("type") || !item["type"].is_string())
      return w + ": expected a spec string or an object with \"type\" (e.g. {\"type\": \"vrchat\"}; docs/outputs.md)";
    std::string spec = item["type"].get<std::string>() + ":", query;
    for (const auto& [key, value] : item.items()) {
      if (key == "type") continue;
      std::string text;
      if (value.is_string()) text = value.get<std::string>();
      else if (value.is_number()) text = value.dump();
      else if (value.is_array()) {
        for (const auto& v : value) {
          if (!v.is_string()) return w + "." + key + ": expected an array of strings";
          text += (text.empty() ? "" : ",") + v.get<std::string>();
        }
      } else {
        return w + "." + key + ": expected a string, a number or an array of strings";
      }
      if (text.find_first_of("&?") != std::string::npos) return w + "." + key + ": must not contain '&' or '?'";
      if (key == "target") spec += text;
      else query += (query.empty() ? "?" : "&") + key + "=" + text;
    }
    config.outputs.push_back(spec + query);
  }
  return {};
}

}  // namespace

// Searched at run time (bodyd/paths/data_files.h): installed, user's, or the build's source tree.
std::filesystem::path bundled_recording_path() { return paths::find_data_file("data/demo/walk.csv").path; }
std::filesystem::path bundled_skeleton_path() { return paths::find_data_file("data/demo/skeleton.bvh").path; }
double configured_head_height_m(const DaemonConfig& c) {
  if (c.head_height_m > 0.0) return c.head_height_m;
  return c.user_height_m > 0.0 ? c.user_height_m * kHeadHeightPerStature : 0.0;
}
std::filesystem::path default_model_path() { return paths::find_data_file("models/bodyd-default.safetensors").path; }

std::string apply_config_json(const json& j, const std::string& source, DaemonConfig& config) {
  if (!j.is_object()) return source + ": the config must be a JSON object {\"key\": value, ...}";
  std::string error;
  for (const auto& [key, value] : j.items()) {
    const std::string w = source + ": " + key;
    bool ok = true;
    if (key == "sources") {
      if (!value.is_array()) return w + ": expected an array of strings like \"replay:FILE\"";
      config.sources.clear();
      for (const auto& s : value) {
        std::string spec;
        if (!get_value(s, w, spec, error)) return error;
        config.sources.push_back(spec);
      }
    } else if (key == "outputs") {
      if (std::string e = apply_outputs(value, w, config); !e.empty()) return e;
    } else if (key == "fast") ok = get_value(value, w, config.fast, error);
    else if (key == "replay_speed") ok = get_value(value, w, config.replay_speed, error);
    else if (key == "loop") ok = get_value(value, w, config.loop, error);
    else if (key == "exit_at_end") ok = get_value(value, w, config.exit_at_end, error);
    else if (key == "sim") {
      if (std::string e = apply_sim(value, w, config.sim); !e.empty()) return e;
    } else if (key == "pub") ok = get_value(value, w, config.pub_endpoint, error);
    else if (key == "control") ok = get_value(value, w, config.control_endpoint, error);
    else if (key == "allow_remote") ok = get_value(value, w, config.allow_remote, error);
    else if (key == "curve_secret_key") ok = get_value(value, w, config.curve_secret_key_file, error);
    else if (key == "curve_allow") ok = get_value(value, w, config.curve_allow_dir, error);
    else if (key == "send_hwm") ok = get_value(value, w, config.send_hwm, error);
    else if (key == "wait_for_subscriber") ok = get_value(value, w, config.wait_for_subscriber, error);
    else if (key == "endpoints_file") ok = get_value(value, w, config.endpoints_file, error);
    else if (key == "record_trackers") ok = get_value(value, w, config.record_trackers_file, error);
    else if (key == "mounting_file") ok = get_value(value, w, config.mounting_file, error);
    else if (key == "overwrite") ok = get_value(value, w, config.record_trackers_overwrite, error);
    else if (key == "rate_hz") ok = get_value(value, w, config.rate_hz, error);
    else if (key == "queue_capacity") ok = get_value(value, w, config.queue_capacity, error);
    else if (key == "queue_max_age_ms") ok = get_value(value, w, config.queue_max_age_ms, error);
    else if (key == "method") ok = get_value(value, w, config.method, error);
    else if (key == "model") ok = get_value(value, w, config.model_path, error);
    else if (key == "models_dir") ok = get_value(value, w, config.models_dir, error);
    else if (key == "user_height_m") ok = get_value(value, w, config.user_height_m, error);
    else if (key == "head_height_m") ok = get_value(value, w, config.head_height_m, error);
    else if (key == "auto_calibrate") ok = get_value(value, w, config.auto_calibrate, error);
    else if (key == "filter") {
      if (std::string e = apply_filter(value, w, config.filter); !e.empty()) return e;
    }
    else if (key == "skeleton") ok = get_value(value, w, config.skeleton_path, error);
    else if (key == "offsets") {
      if (std::string e = apply_offsets(value, w, config); !e.empty()) return e;
    } else if (key == "log_level") ok = get_value(value, w, config.log_level, error);
    else return w + ": unknown key (the keys are listed in docs/daemon.md)";
    if (!ok) return error;
  }
  return {};
}

std::string load_config_file(const std::filesystem::path& path, DaemonConfig& config) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return path.string() + ": cannot open the config file";
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string text = buffer.str();
  json j = json::parse(text, nullptr, /*allow_exceptions=*/false, /*ignore_comments=*/true);
  if (j.is_discarded()) {
    // Find where: parse again with exceptions only to learn the byte offset.
    std::size_t byte = 0;
    std::string what = "not valid JSON";
    try {
      const json ignored = json::parse(text, nullptr, true, true);
      (void)ignored;
    } catch (const json::parse_error& e) {
      byte = e.byte;
      what = e.what();
    } catch (const json::exception& e) {
      // A number that overflows a double (1e400) is an out_of_range error, with no byte offset.
      what = e.what();
      return path.string() + ": " + what + " (numbers must fit a double; see docs/daemon.md, \"Limits\")";
    }
    int line = 1, column = 1;
    for (std::size_t i = 0; i + 1 < byte && i < text.size(); ++i) {
      if (text[i] == '\n') ++line, column = 1;
      else ++column;
    }
    return path.string() + ":" + std::to_string(line) + ":" + std::to_string(column) + ": " + what;
  }
  return apply_config_json(j, path.string(), config);
}

std::string check_reload_model_path(const std::filesystem::path& requested, const DaemonConfig& config) {
  std::error_code ec;
  const std::filesystem::path configured = config.model_path.empty() ? default_model_path() : std::filesystem::path(config.model_path);
  const std::filesystem::path dir = config.models_dir.empty() ? default_model_path().parent_path() : std::filesystem::path(config.models_dir);
  const auto file = std::filesystem::weakly_canonical(requested, ec);
  if (ec) return requested.string() + ": cannot resolve the path";
  if (file == std::filesystem::weakly_canonical(configured, ec)) return {};
  const auto root = std::filesystem::weakly_canonical(dir, ec);
  if (!ec) {
    const auto rel = file.lexically_relative(root);
    if (!rel.empty() && *rel.begin() != ".." && rel != ".") return {};
  }
  return requested.string() + ": not the configured model and not under the models directory " + root.string() +
         " (reload-model loads only those; start bodyd with --models-dir DIR to allow another directory)";
}

std::string parse_offset_flag(const std::string& text, DaemonConfig& config) {
  const std::string where = "--offset " + text;
  const auto eq = text.find('=');
  if (eq == std::string::npos) return where + ": expected ROLE=x,y,z or ROLE=x,y,z,qx,qy,qz,qw";
  const auto role = role_from_name(text.substr(0, eq));
  if (!role) return where + ": unknown role \"" + text.substr(0, eq) + "\" (head, left_hand, right_hand)";
  std::vector<double> values;
  std::stringstream ss(text.substr(eq + 1));
  std::string item;
  while (std::getline(ss, item, ',')) {
    try {
      std::size_t used = 0;
      values.push_back(std::stod(item, &used));
      if (used != item.size()) throw std::invalid_argument(item);
    } catch (const std::exception&) {
      return where + ": \"" + item + "\" is not a number";
    }
  }
  if (values.size() != 3 && values.size() != 7)
    return where + ": expected 3 numbers (position, metres) or 7 (position, then rotation x,y,z,w)";
  DeviceOffset offset;
  if (std::string e = offset_from_values(values, where, offset); !e.empty()) return e;
  config.offsets[static_cast<int>(*role)] = offset;
  return {};
}

std::string validate_config(const DaemonConfig& c) {
  if (!c.curve_allow_dir.empty() && c.curve_secret_key_file.empty())
    return "curve_allow (--curve-allow) needs curve_secret_key (--curve-secret-key): the allow-list is of CURVE clients";
  if (!(c.replay_speed > 0.0) || !(c.replay_speed <= limits::kMaxReplaySpeed))
    return "replay_speed (--speed) must be > 0 and at most " + fmt_number(limits::kMaxReplaySpeed) + ", not " +
           fmt_number(c.replay_speed) + " (use --fast to replay as fast as possible)";
  if (!(c.rate_hz >= 0.0) || !(c.rate_hz <= limits::kMaxRateHz))
    return "rate_hz must be between 0 (one pose per head sample) and " + fmt_number(limits::kMaxRateHz) + ", not " +
           fmt_number(c.rate_hz);
  if (c.queue_capacity < 16 || c.queue_capacity > (1u << 20)) return "queue_capacity must be in 16 .. 1048576";
  if (!(c.queue_max_age_ms >= 0.0) || !(c.queue_max_age_ms <= 60000.0))
    return "queue_max_age_ms (--queue-max-age-ms) must be between 0 (never drop for age) and 60000, not " +
           fmt_number(c.queue_max_age_ms);
  if (c.send_hwm < 1) return "send_hwm must be >= 1";
  // A wildcard port (tcp://127.0.0.1:*) gives each socket its own ephemeral port.
  if (c.pub_endpoint == c.control_endpoint && !c.pub_endpoint.ends_with(":*") && !c.pub_endpoint.ends_with(":0"))
    return "pub and control are the same endpoint (" + c.pub_endpoint + "): give each socket its own";
  if (c.method != "diffusion" && c.method != "ik") return "method \"" + c.method + "\": expected diffusion or ik";
  for (auto [name, h] : {std::pair{"user_height_m", c.user_height_m}, std::pair{"head_height_m", c.head_height_m}}) {
    if (!std::isfinite(h) || h < 0.0 || h > limits::kMaxUserHeightM || (h > 0.0 && h < limits::kMinUserHeightM))
      return std::string(name) + " must be 0 (the model's size) or a height in metres between " +
             fmt_number(limits::kMinUserHeightM) + " and " + fmt_number(limits::kMaxUserHeightM) + " (e.g. 1.75), not " +
             fmt_number(h);
  }
  if (c.user_height_m > 0.0 && c.head_height_m > 0.0)
    return "give user_height_m (body height) or head_height_m (standing head height), not both";
  if (std::string e = validate(c.filter); !e.empty())
    return e + " (the \"filter\" keys: docs/daemon.md, \"Tracker filter\")";
  static const char* kLevels[] = {"trace", "debug", "info", "warn", "error", "critical", "off"};
  bool level_ok = false;
  for (const char* l : kLevels) level_ok |= c.log_level == l;
  if (!level_ok) return "log_level \"" + c.log_level + "\": expected trace, debug, info, warn, error, critical or off";
  if (c.exit_at_end && c.loop) return "exit_at_end and loop contradict each other: a looped replay never ends";
  if (const std::string e = c.sim.validate(); !e.empty()) return "sim: " + e;
  return {};
}

std::string check_specs(const DaemonConfig& c) {
  std::string error;
  for (const std::string& text : c.sources)
    if (std::string e = drivers::check_source_spec(text); !e.empty()) return e;
  // Made, not opened: the factories check the target and the options.
  const OutputEnv env{c};
  for (const std::string& text : c.outputs) {
    OutputSpec spec;
    double rate_hz = 0.0;
    if (!parse_output_spec(text, spec, error) || !take_rate_option(spec, rate_hz, error) || !make_output(spec, env, error))
      return error;
  }
  return {};
}

json config_to_json(const DaemonConfig& c) {
  json offsets = json::object();
  for (Role r : kRoles) {
    const auto& o = c.offsets[static_cast<int>(r)];
    if (!o) continue;
    offsets[std::string(role_name(r))] = {
        {"position_m", {o->position_m.x(), o->position_m.y(), o->position_m.z()}},
        {"rotation_xyzw", {o->rotation.x(), o->rotation.y(), o->rotation.z(), o->rotation.w()}}};
  }
  return json{
      {"sources", c.sources},
      {"fast", c.fast},
      {"replay_speed", c.replay_speed},
      {"loop", c.loop},
      {"exit_at_end", c.exit_at_end},
      {"sim",
       {{"rate_hz", c.sim.rate_hz},
        {"head_rate_hz", c.sim.role_rate_hz[0]},
        {"left_hand_rate_hz", c.sim.role_rate_hz[1]},
        {"right_hand_rate_hz", c.sim.role_rate_hz[2]},
        {"position_noise_mm", c.sim.position_noise_mm},
        {"rotation_noise_deg", c.sim.rotation_noise_deg},
        {"latency_ms", c.sim.latency_ms},
        {"jitter_ms", c.sim.jitter_ms},
        {"dropout_rate_hz", c.sim.dropout_rate_hz},
        {"dropout_mean_ms", c.sim.dropout_mean_ms},
        {"seed", c.sim.seed}}},
      {"pub", c.pub_endpoint},
      {"control", c.control_endpoint},
      {"allow_remote", c.allow_remote},
      {"curve_secret_key", c.curve_secret_key_file},
      {"curve_allow", c.curve_allow_dir},
      {"send_hwm", c.send_hwm},
      {"wait_for_subscriber", c.wait_for_subscriber},
      {"endpoints_file", c.endpoints_file},
      {"record_trackers", c.record_trackers_file},
      {"mounting_file", c.mounting_file},
      {"overwrite", c.record_trackers_overwrite},
      {"outputs", c.outputs},
      {"rate_hz", c.rate_hz},
      {"queue_capacity", c.queue_capacity},
      {"queue_max_age_ms", c.queue_max_age_ms},
      {"method", c.method},
      {"model", c.model_path},
      {"models_dir", c.models_dir},
      {"skeleton", c.skeleton_path},
      {"user_height_m", c.user_height_m},
      {"head_height_m", c.head_height_m},
      {"auto_calibrate", c.auto_calibrate},
      {"filter",
       {{"enabled", c.filter.enabled},
        {"min_cutoff_hz", c.filter.min_cutoff_hz},
        {"beta_per_m_s", c.filter.beta_per_m_s},
        {"d_cutoff_hz", c.filter.d_cutoff_hz},
        {"rot_min_cutoff_hz", c.filter.rot_min_cutoff_hz},
        {"rot_beta_per_rad_s", c.filter.rot_beta_per_rad_s}}},
      {"offsets", offsets},
      {"log_level", c.log_level},
  };
}

CliResult parse_command_line(int argc, const char* const* argv, DaemonConfig& config) {
  CliResult result;
  // The config files are read first so that flags override them: the user's config
  // (--user-config, what the systemd unit runs), then --config FILE.
  for (int i = 1; i < argc; ++i) {
    if (std::string_view(argv[i]) != "--user-config") continue;
    const std::filesystem::path user = paths::user_config_file();
    std::error_code ec;
    if (user.empty()) {
      result.notes.push_back("--user-config: neither XDG_CONFIG_HOME nor HOME is set: no user config read");
    } else if (!std::filesystem::exists(user, ec)) {
      result.notes.push_back("--user-config: " + user.string() + " does not exist: using the defaults (docs/install.md)");
    } else if (std::string e = load_config_file(user, config); !e.empty()) {
      std::cerr << "bodyd: " << e << "\n";
      result.action = CliResult::Action::Exit;
      result.exit_code = 2;
      return result;
    } else {
      result.notes.push_back("config: " + user.string());
    }
    break;
  }
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    std::string path;
    if (arg == "--config" && i + 1 < argc) path = argv[i + 1];
    else if (arg.rfind("--config=", 0) == 0) path = arg.substr(9);
    if (path.empty()) continue;
    if (std::string e = load_config_file(path, config); !e.empty()) {
      std::cerr << "bodyd: " << e << "\n";
      result.action = CliResult::Action::Exit;
      result.exit_code = 2;
      return result;
    }
  }

  CLI::App app{"bodyd: full-body pose from head and hand trackers, published over ZeroMQ (docs/daemon.md)"};
  app.set_version_flag("--version", "bodyd 0.1.0");
  std::string config_file;
  app.add_option("--config", config_file, "JSON config file (keys: docs/daemon.md); flags override it");
  bool user_config = false;
  app.add_flag("--user-config", user_config,
               "read $XDG_CONFIG_HOME/bodyd/config.json (~/.config/bodyd/config.json) when it exists, before --config");

  std::vector<std::string> source_flags, replay_flags, sim_flags, offset_flags;
  app.add_option("--source", source_flags,
                 "tracker source: " + drivers::source_syntax_list(", ") +
                     " (docs/drivers.md, docs/vr-apps.md); repeatable. Default: the bundled recording, looped");
  app.add_option("--replay", replay_flags, "replay a tracker log (same as --source replay:LOG)");
  app.add_option("--sim", sim_flags, "simulated trackers from a BVH clip (same as --source sim:FILE.bvh)");
  app.add_flag("--fast", config.fast, "replay as fast as possible (lossless) instead of at the log's pace");
  app.add_option("--speed", config.replay_speed, "paced replay speed factor")->check(CLI::PositiveNumber);
  app.add_flag("--loop", config.loop, "start replays again at the end");
  app.add_flag("--exit-at-end", config.exit_at_end, "exit when every replay has been published");
  app.add_option("--sim-seed", config.sim.seed, "random seed of the simulated trackers");
  app.add_option("--pub", config.pub_endpoint, "pose stream endpoint (PUB), e.g. tcp://127.0.0.1:5570");
  std::vector<std::string> output_flags;
  app.add_option("--output", output_flags,
                 "another output, SCHEME:TARGET[?KEY=VALUE&...], e.g. vrchat:127.0.0.1:9000?slots=hip,feet "
                 "(docs/outputs.md); repeatable");
  app.add_option("--control", config.control_endpoint, "control endpoint (REP, JSON), or \"none\"");
  app.add_flag("--allow-remote", config.allow_remote,
               "allow binding to non-loopback addresses: ZeroMQ sockets (use CURVE!) and the vrchat:/vmc:/udp: "
               "inputs (OSC and UDP have no authentication)");
  app.add_option("--curve-secret-key", config.curve_secret_key_file,
                 "CURVE server secret key file (from --gen-keys): encrypt and authenticate both sockets");
  app.add_option("--send-hwm", config.send_hwm, "poses queued per subscriber before dropping")->check(CLI::PositiveNumber);
  app.add_flag("--wait-for-subscriber", config.wait_for_subscriber,
               "start the sources only when a subscriber has subscribed");
  app.add_option("--endpoints-file", config.endpoints_file, "write the bound endpoints here as JSON");
  app.add_option("--curve-allow", config.curve_allow_dir,
                 "only clients whose public key is in DIR (NAME.public files) may connect (needs --curve-secret-key)");
  app.add_option("--mounting-file", config.mounting_file,
                 "keep the calibration pose's device mountings in this JSON file across restarts (docs/daemon.md)");
  app.add_option("--record-trackers", config.record_trackers_file,
                 "write every tracker sample received to FILE (tracker log v1; replay it with --replay FILE --fast)");
  app.add_flag("--overwrite", config.record_trackers_overwrite,
               "--record-trackers may replace an existing file (without it an existing file is refused)");
  app.add_option("--rate-hz", config.rate_hz, "output rate limit; 0: one pose per head sample")->check(CLI::NonNegativeNumber);
  app.add_option("--queue-capacity", config.queue_capacity, "tracker samples the queue holds");
  app.add_option("--queue-max-age-ms", config.queue_max_age_ms,
                 "drop queued samples that arrived more than this before the newest (0: never)");
  app.add_option("--method", config.method, "reconstruction: diffusion (default) or ik");
  app.add_option("--model", config.model_path, "model file (default models/bodyd-default.safetensors)");
  app.add_option("--models-dir", config.models_dir,
                 "reload-model loads only --model or files under this directory (default: the default model's)");
  app.add_option("--skeleton", config.skeleton_path, "BVH file whose skeleton the ik method uses (default: bundled)");
  app.add_option("--user-height-m", config.user_height_m,
                 "user's body height in metres (approximate scaling; 0: the model's size)");
  app.add_option("--head-height-m", config.head_height_m,
                 "user's standing head height in metres (exact scaling; 0: the model's size)");
  app.add_flag("!--no-auto-calibrate", config.auto_calibrate,
               "do not calibrate the user's size from the head's first still half second (docs/daemon.md, "
               "\"Calibration\")");
  bool no_filter = false;
  app.add_flag("--no-filter", no_filter, "no One Euro filter on the tracker samples (config \"filter\": {\"enabled\": false})");
  app.add_option("--offset", offset_flags,
                 "device offset ROLE=x,y,z[,qx,qy,qz,qw] (metres; rotation x,y,z,w), repeatable");
  app.add_option("--log-level", config.log_level, "trace, debug, info, warn, error, off");
  std::string gen_keys_dir;
  app.add_option("--gen-keys", gen_keys_dir, "write a CURVE key pair to DIR (server.public, server.secret) and exit");
  std::string gen_keys_client;
  app.add_option("--client", gen_keys_client,
                 "with --gen-keys: a client's key pair instead, DIR/NAME.public (for --curve-allow) and DIR/NAME.secret");
  bool list_devices = false;
  app.add_flag("--list-devices", list_devices, "list the tracker devices bodyd can see (for --source) and exit");
  bool print_config = false;
  app.add_flag("--print-config", print_config, "print the effective configuration as JSON and exit");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    result.action = CliResult::Action::Exit;
    // app.exit prints the message; --help and --version exit 0, and every bad command line
    // exits 2 as documented (CLI11's own codes are 105, 109, ...; issue 11).
    result.exit_code = app.exit(e) == 0 ? 0 : 2;
    return result;
  }
  std::vector<std::string> sources = source_flags;
  for (const auto& r : replay_flags) sources.push_back("replay:" + r);
  for (const auto& s : sim_flags) sources.push_back("sim:" + s);
  if (!sources.empty()) config.sources = sources;
  if (!output_flags.empty()) config.outputs = output_flags;
  if (no_filter) config.filter.enabled = false;
  // The systemd unit's daemon keeps its calibration pose across restarts by default.
  if (user_config && config.mounting_file.empty()) config.mounting_file = paths::user_state_file("mounting.json").string();
  for (const auto& o : offset_flags) {
    if (std::string e = parse_offset_flag(o, config); !e.empty()) {
      std::cerr << "bodyd: " << e << "\n";
      result.action = CliResult::Action::Exit;
      result.exit_code = 2;
      return result;
    }
  }
  if (list_devices) {
    result.action = CliResult::Action::ListDevices;
    return result;
  }
  if (!gen_keys_client.empty()) {
    bool name_ok = gen_keys_client != "server" && gen_keys_client.front() != '.';
    for (char ch : gen_keys_client) name_ok &= std::isalnum(static_cast<unsigned char>(ch)) || ch == '-' || ch == '_' || ch == '.';
    if (gen_keys_dir.empty() || !name_ok) {
      std::cerr << "bodyd: --client NAME goes with --gen-keys DIR; NAME is letters, digits, '-', '_', '.' (not "
                   "\"server\"), e.g. --gen-keys ~/.config/bodyd/clients --client quest\n";
      result.action = CliResult::Action::Exit;
      result.exit_code = 2;
      return result;
    }
  }
  if (!gen_keys_dir.empty()) {
    result.action = CliResult::Action::GenKeys;
    result.gen_keys_dir = gen_keys_dir;
    if (!gen_keys_client.empty()) result.gen_keys_name = gen_keys_client;
    return result;
  }
  std::string e = validate_config(config);
  if (e.empty()) e = check_specs(config);
  if (!e.empty()) {
    std::cerr << "bodyd: " << e << "\n";
    result.action = CliResult::Action::Exit;
    result.exit_code = 2;
    return result;
  }
  if (print_config) result.action = CliResult::Action::PrintConfig;
  return result;
}

}  // namespace bodyd::daemon
