// The config file's parser, the validator, the printer and the command-line flags, each driven by
// the config key table (config_keys.cpp; bodyd/daemon/config_keys.h).
#include "bodyd/daemon/config.h"

#include "bodyd/daemon/config_keys.h"
#include "bodyd/io/output.h"
#include "bodyd/io/open_source.h"
#include "bodyd/motion/limits.h"
#include "bodyd/paths/data_files.h"
#include "config_readers.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <deque>
#include <limits>
#include <fstream>
#include <iostream>
#include <sstream>
#include <type_traits>
#include <variant>


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

// "{keys}" in a group's unknown-key message: its keys, in the table's order.
std::string group_keys(std::string_view group) {
  std::string keys;
  for (const ConfigKey& row : config_keys())
    if (row.group == group) keys += (keys.empty() ? "" : ", ") + std::string(row.name);
  return keys;
}

const ConfigKey* find_key(std::string_view group, std::string_view name) {
  for (const ConfigKey& row : config_keys())
    if (row.group == group && row.name == name) return &row;
  return nullptr;
}

const ConfigGroup* find_group(std::string_view name) {
  for (const ConfigGroup& group : config_groups())
    if (group.name == name) return &group;
  return nullptr;
}

// Reads one key's value from the file into its member.
std::string read_key(const ConfigKey& row, const json& value, const std::string& where, DaemonConfig& config) {
  if (row.read) return row.read(value, where, config);
  std::string error;
  const bool ok = with_member(row, config, [&](auto& member) -> bool {
    using T = std::remove_reference_t<decltype(member)>;
    if constexpr (std::is_same_v<T, std::vector<std::string>>) {
      if (!value.is_array()) {
        error = where + ": expected an array of strings";
        return false;
      }
      member.clear();
      for (const auto& item : value) {
        std::string text;
        if (!get_value(item, where, text, error)) return false;
        member.push_back(text);
      }
      return true;
    } else if constexpr (std::is_same_v<T, DeviceOffsets>) {
      error = where + ": this key has no reader (config_keys.cpp)";  // its row names one
      return false;
    } else {
      return get_value(value, where, member, error);
    }
  });
  return ok ? std::string() : error;
}

// The value of one key as the file writes it.
json print_key(const ConfigKey& row, const DaemonConfig& config) {
  if (row.print) return row.print(config);
  DaemonConfig copy = config;  // the rows' accessors take a mutable configuration; this only reads
  return with_member(row, copy, [](const auto& member) -> json {
    if constexpr (std::is_same_v<std::remove_cvref_t<decltype(member)>, DeviceOffsets>)
      return json();  // its row names a printer
    else
      return json(member);
  });
}

// {key}, {flag}, {min}, {max}, {value} in a range's message.
std::string range_message(const ConfigKey& row, double value, bool integer) {
  const auto number = [](double x) {
    return std::floor(x) == x && std::fabs(x) < 1e15 ? std::to_string(static_cast<long long>(x)) : fmt_number(x);
  };
  std::string text(row.range.error);
  const std::pair<std::string_view, std::string> fields[] = {
      {"{key}", row.full_name()},
      {"{flag}", row.flag.starts_with('!') ? row.flag.substr(1) : row.flag},
      {"{min}", number(row.range.min)},
      {"{max}", number(row.range.max)},
      {"{value}", integer ? number(value) : fmt_number(value)}};
  for (const auto& [name, replacement] : fields)
    for (std::size_t at = text.find(name); at != std::string::npos; at = text.find(name, at + replacement.size()))
      text.replace(at, name.size(), replacement);
  return text;
}

// A key's own check: its range or its choices. Empty when fine.
std::string check_key(const ConfigKey& row, const DaemonConfig& config) {
  DaemonConfig copy = config;
  std::string error;
  // The simulator's and the filters' rows have no range or choices here (their own validate()).
  with_member(row, copy, [&](const auto& member) {
    using T = std::remove_cvref_t<decltype(member)>;
    if constexpr (std::is_arithmetic_v<T> && !std::is_same_v<T, bool>) {
      if (row.range.error.empty()) return;
      const double v = static_cast<double>(member);
      const bool in_range = std::isfinite(v) && (row.range.min_exclusive ? v > row.range.min : v >= row.range.min) &&
                            v <= row.range.max;
      if (!in_range && !(row.range.zero_allowed && v == 0.0)) error = range_message(row, v, std::is_integral_v<T>);
    } else if constexpr (std::is_same_v<T, std::string>) {
      if (row.choices.empty()) return;
      std::vector<std::string_view> choices;
      for (std::size_t start = 0; start <= row.choices.size();) {
        const std::size_t comma = std::min(row.choices.find(',', start), row.choices.size());
        choices.push_back(row.choices.substr(start, comma - start));
        start = comma + 1;
      }
      if (std::find(choices.begin(), choices.end(), member) != choices.end()) return;
      std::string expected;
      for (std::size_t i = 0; i < choices.size(); ++i)
        expected += (i == 0 ? "" : i + 1 == choices.size() ? " or " : ", ") + std::string(choices[i]);
      error = row.full_name() + " \"" + member + "\": expected " + expected;
    }
  });
  return error;
}

}  // namespace

// "sources": ["replay:FILE", ...].
std::string read_sources(const json& j, const std::string& where, DaemonConfig& config) {
  if (!j.is_array()) return where + ": expected an array of strings like \"replay:FILE\"";
  config.sources.clear();
  std::string error;
  for (const auto& s : j) {
    std::string spec;
    if (!get_value(s, where, spec, error)) return error;
    config.sources.push_back(spec);
  }
  return {};
}

json print_offsets(const DaemonConfig& c) {
  json offsets = json::object();
  for (Role r : kXrRoles) {
    const auto& o = c.offsets[static_cast<int>(r)];
    if (!o) continue;
    offsets[std::string(role_name(r))] = {
        {"position_m", {o->position_m.x(), o->position_m.y(), o->position_m.z()}},
        {"rotation_xyzw", {o->rotation.x(), o->rotation.y(), o->rotation.z(), o->rotation.w()}}};
  }
  return offsets;
}

std::string read_offsets(const json& j, const std::string& where, DaemonConfig& config) {
  if (!j.is_object()) return where + ": expected an object with keys head, left_hand, right_hand";
  for (const auto& [key, value] : j.items()) {
    const std::string w = where + "." + key;
    const auto role = role_from_name(key);
    if (!role || !is_xr_role(*role))
      return w + ": unknown role (expected head, left_hand or right_hand: offsets are for the headset and controllers)";
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

// "outputs": a list of specs ("vrchat:127.0.0.1:9000?slots=hip,feet") or objects
// {"type": "vrchat", "target": "127.0.0.1:9000", "slots": ["hip", "feet"], "rate": 60}
// (docs/outputs.md). Objects become specs; the output checks its options when it is made.
std::string read_outputs(const json& j, const std::string& where, DaemonConfig& config) {
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
  for (const auto& [key, value] : j.items()) {
    const std::string w = source + ": " + key;
    if (const ConfigKey* row = find_key("", key)) {
      if (std::string e = read_key(*row, value, w, config); !e.empty()) return e;
    } else if (const ConfigGroup* group = find_group(key)) {
      if (!value.is_object()) return w + ": " + std::string(group->not_object);
      for (const auto& [inner, inner_value] : value.items()) {
        const std::string wi = w + "." + inner;
        const ConfigKey* inner_row = find_key(group->name, inner);
        if (!inner_row) {
          std::string message(group->unknown_key);
          if (const auto at = message.find("{keys}"); at != std::string::npos)
            message.replace(at, 6, group_keys(group->name));
          return wi + ": " + message;
        }
        if (std::string e = read_key(*inner_row, inner_value, wi, config); !e.empty()) return e;
      }
    } else {
      return w + ": unknown key (the keys are listed in docs/daemon.md)";
    }
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
  // Each key's own range or choices (its row), then what concerns several keys.
  for (const ConfigKey& row : config_keys())
    if (std::string e = check_key(row, c); !e.empty()) return e;
  if (!c.curve_allow_dir.empty() && c.curve_secret_key_file.empty())
    return "curve_allow (--curve-allow) needs curve_secret_key (--curve-secret-key): the allow-list is of CURVE clients";
  // A wildcard port (tcp://127.0.0.1:*) gives each socket its own ephemeral port.
  if (c.pub_endpoint == c.control_endpoint && !c.pub_endpoint.ends_with(":*") && !c.pub_endpoint.ends_with(":0"))
    return "pub and control are the same endpoint (" + c.pub_endpoint + "): give each socket its own";
  if (c.user_height_m > 0.0 && c.head_height_m > 0.0)
    return "give user_height_m (body height) or head_height_m (standing head height), not both";
  if (std::string e = validate(c.filter); !e.empty())
    return e + " (the \"filter\" keys: docs/daemon.md, \"Tracker filter\")";
  if (std::string e = validate(c.body_filter); !e.empty())
    return e + " (the \"body_filter\" keys: docs/daemon.md, \"Body filter\")";
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
  json out = json::object();
  for (const ConfigKey& row : config_keys()) {
    json& slot = row.group.empty() ? out[std::string(row.name)] : out[std::string(row.group)][std::string(row.name)];
    slot = print_key(row, c);
  }
  return out;
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

  // One flag per key that has one (its row); a list key's values are collected here and
  // replace the file's list when given.
  std::deque<std::pair<const ConfigKey*, std::vector<std::string>>> list_flags;
  for (const ConfigKey& row : config_keys()) {
    if (row.flag.empty()) continue;
    CLI::Option* option = with_member(row, config, [&](auto& member) -> CLI::Option* {
      using T = std::remove_reference_t<decltype(member)>;
      if constexpr (std::is_same_v<T, bool>)
        return app.add_flag(row.flag, member, row.help);
      else if constexpr (std::is_same_v<T, std::vector<std::string>> || std::is_same_v<T, DeviceOffsets>)
        return app.add_option(row.flag, list_flags.emplace_back(&row, std::vector<std::string>{}).second, row.help);
      else
        return app.add_option(row.flag, member, row.help);
    });
    if (row.flag_check == FlagCheck::Positive) option->check(CLI::PositiveNumber);
    if (row.flag_check == FlagCheck::NonNegative) option->check(CLI::NonNegativeNumber);
  }
  std::vector<std::string> replay_flags, sim_flags;
  app.add_option("--replay", replay_flags, "replay a tracker log (same as --source replay:LOG)");
  app.add_option("--sim", sim_flags, "simulated trackers from a BVH clip (same as --source sim:FILE.bvh)");
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
  for (auto& [row, values] : list_flags) {
    if (row->name == "sources") {  // --replay LOG and --sim FILE are --source replay:LOG, sim:FILE
      for (const auto& r : replay_flags) values.push_back("replay:" + r);
      for (const auto& s : sim_flags) values.push_back("sim:" + s);
    }
    if (std::holds_alternative<ConfigRef<DeviceOffsets>>(row->field)) {
      for (const auto& o : values) {
        if (std::string e = parse_offset_flag(o, config); !e.empty()) {
          std::cerr << "bodyd: " << e << "\n";
          result.action = CliResult::Action::Exit;
          result.exit_code = 2;
          return result;
        }
      }
    } else if (!values.empty()) {
      std::get<ConfigRef<std::vector<std::string>>>(row->field)(config) = values;
    }
  }
  // Every bodyd keeps its calibration across restarts (issue 43 item 13: a plain `bodyd` forgot
  // it): unless a mounting file is configured ("none": nowhere), the user's state file.
  if (config.mounting_file.empty()) {
    config.mounting_file = paths::user_state_file("mounting.json").string();
    if (config.mounting_file.empty())
      result.notes.push_back("mounting_file: neither XDG_STATE_HOME nor HOME is set: the calibration is not kept "
                             "across restarts (--mounting-file FILE keeps it; docs/daemon.md, \"Device mounting\")");
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
