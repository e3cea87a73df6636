// The config key table: every key of the config file, its flag, range, help and doc section
// (bodyd/daemon/config_keys.h says what each column drives).
#include "bodyd/daemon/config_keys.h"

#include "bodyd/io/open_source.h"
#include "bodyd/io/output.h"
#include "bodyd/motion/limits.h"
#include "config_readers.h"

#include <climits>

namespace bodyd::daemon {
namespace {

template <auto Member>
auto& at(DaemonConfig& c) {
  return c.*Member;
}
constexpr std::string_view kCommandLine = "Command line";
constexpr std::string_view kTrackerFilter = "Tracker filter";
constexpr std::string_view kBodyFilter = "Body filter";

constexpr KeyRange kHeightRange{limits::kMinUserHeightM, limits::kMaxUserHeightM, false, true,
                                "{key} must be 0 (the model's size) or a height in metres between {min} and {max} "
                                "(e.g. 1.75), not {value}"};

// --output's help: the spec's form and one line per registered output kind (io/outputs.cpp).
std::string outputs_help() {
  std::string help = "another output, SCHEME:TARGET[?KEY=VALUE&...], e.g. vrchat:127.0.0.1:9000?slots=hip,feet "
                     "(docs/outputs.md); repeatable. The kinds:";
  for (const OutputKind& kind : output_kinds()) help += "\n  " + std::string(kind.help);
  return help;
}

std::vector<ConfigKey> make_rows() {
  std::vector<ConfigKey> rows;
  const auto add = [&](ConfigKey row) {
    if (row.doc.empty()) row.doc = kCommandLine;
    rows.push_back(std::move(row));
  };
  add({.name = "sources", .field = &at<&DaemonConfig::sources>, .flag = "--source",
       .help = "tracker source: " + drivers::source_syntax_list(", ") +
               " (docs/drivers.md, docs/vr-apps.md); repeatable. Default: the bundled recording, looped",
       .read = read_sources});
  add({.name = "fast", .field = &at<&DaemonConfig::fast>, .flag = "--fast",
       .help = "replay as fast as possible (lossless) instead of at the log's pace"});
  add({.name = "replay_speed", .field = &at<&DaemonConfig::replay_speed>, .flag = "--speed",
       .flag_check = FlagCheck::Positive,
       .range = {0.0, limits::kMaxReplaySpeed, true, false,
                 "{key} ({flag}) must be > 0 and at most {max}, not {value} (use --fast to replay as fast as possible)"},
       .help = "paced replay speed factor"});
  add({.name = "loop", .field = &at<&DaemonConfig::loop>, .flag = "--loop", .help = "start replays again at the end"});
  add({.name = "exit_at_end", .field = &at<&DaemonConfig::exit_at_end>, .flag = "--exit-at-end",
       .help = "exit when every replay has been published"});
  // The simulator's own rows: "sim": {...} in the file, --sim-FLAG on the command line
  // (checked by SimOptions::validate()).
  for (const SimOptionKey& sim : sim_option_keys())
    add({.group = "sim", .name = sim.key, .field = &sim, .flag = "--sim-" + std::string(sim.flag.substr(2)),
         .help = std::string(sim.help) + " (the simulated trackers of sim: sources)"});
  add({.name = "pub", .field = &at<&DaemonConfig::pub_endpoint>, .flag = "--pub",
       .help = "pose stream endpoint (PUB), e.g. tcp://127.0.0.1:5570"});
  add({.name = "outputs", .field = &at<&DaemonConfig::outputs>, .flag = "--output",
       .help = outputs_help(),
       .read = read_outputs});
  add({.name = "control", .field = &at<&DaemonConfig::control_endpoint>, .flag = "--control",
       .help = "control endpoint (REP, JSON), or \"none\""});
  add({.name = "allow_remote", .field = &at<&DaemonConfig::allow_remote>, .flag = "--allow-remote",
       .help = "allow binding to non-loopback addresses: ZeroMQ sockets (use CURVE!) and the vrchat:/vmc:/udp: "
               "inputs (OSC and UDP have no authentication)"});
  add({.name = "curve_secret_key", .field = &at<&DaemonConfig::curve_secret_key_file>, .flag = "--curve-secret-key",
       .help = "CURVE server secret key file (from --gen-keys): encrypt and authenticate both sockets"});
  add({.name = "send_hwm", .field = &at<&DaemonConfig::send_hwm>, .flag = "--send-hwm",
       .flag_check = FlagCheck::Positive, .range = {1.0, INT_MAX, false, false, "{key} must be >= {min}"},
       .help = "poses queued per subscriber before dropping"});
  add({.name = "wait_for_subscriber", .field = &at<&DaemonConfig::wait_for_subscriber>, .flag = "--wait-for-subscriber",
       .help = "start the sources only when a subscriber has subscribed"});
  add({.name = "endpoints_file", .field = &at<&DaemonConfig::endpoints_file>, .flag = "--endpoints-file",
       .help = "write the bound endpoints here as JSON"});
  add({.name = "curve_allow", .field = &at<&DaemonConfig::curve_allow_dir>, .flag = "--curve-allow",
       .help = "only clients whose public key is in DIR (NAME.public files) may connect (needs --curve-secret-key)"});
  add({.name = "mounting_file", .field = &at<&DaemonConfig::mounting_file>, .flag = "--mounting-file",
       .help = "keep the calibration (device mountings, head height) in this JSON file across restarts; default "
               "$XDG_STATE_HOME/bodyd/mounting.json, \"none\": not kept (docs/daemon.md)"});
  add({.name = "record_trackers", .field = &at<&DaemonConfig::record_trackers_file>, .flag = "--record-trackers",
       .help = "write every tracker sample received to FILE (tracker log v1; replay it with --replay FILE --fast)"});
  add({.name = "overwrite", .field = &at<&DaemonConfig::record_trackers_overwrite>, .flag = "--overwrite",
       .help = "--record-trackers may replace an existing file (without it an existing file is refused)"});
  add({.name = "rate_hz", .field = &at<&DaemonConfig::rate_hz>, .flag = "--rate-hz",
       .flag_check = FlagCheck::NonNegative,
       .range = {limits::kMinPoseRateHz, limits::kMaxRateHz, false, true,
                 "{key} ({flag}) must be 0 (one pose per head sample) or between {min} and {max} poses a second, not {value}"},
       .help = "output rate limit; 0: one pose per head sample"});
  add({.name = "queue_capacity", .field = &at<&DaemonConfig::queue_capacity>, .flag = "--queue-capacity",
       .range = {static_cast<double>(kMinQueueCapacity), static_cast<double>(kMaxQueueCapacity), false, false,
                 "{key} must be in {min} .. {max}"},
       .help = "tracker samples the queue holds"});
  add({.name = "queue_max_age_ms", .field = &at<&DaemonConfig::queue_max_age_ms>, .flag = "--queue-max-age-ms",
       .range = {0.0, kMaxQueueMaxAgeMs, false, false,
                 "{key} ({flag}) must be between 0 (never drop for age) and {max}, not {value}"},
       .help = "drop queued samples that arrived more than this before the newest (0: never)"});
  add({.name = "method", .field = &at<&DaemonConfig::method>, .flag = "--method", .choices = "diffusion,ik",
       .help = "reconstruction: diffusion (default) or ik"});
  add({.name = "model", .field = &at<&DaemonConfig::model_path>, .flag = "--model",
       .help = "model file (default models/bodyd-default.safetensors)"});
  add({.name = "models_dir", .field = &at<&DaemonConfig::models_dir>, .flag = "--models-dir",
       .help = "reload-model loads only --model or files under this directory (default: the default model's)"});
  add({.name = "skeleton", .field = &at<&DaemonConfig::skeleton_path>, .flag = "--skeleton",
       .help = "BVH file whose skeleton the ik method uses (default: bundled)"});
  add({.name = "user_height_m", .field = &at<&DaemonConfig::user_height_m>, .flag = "--user-height-m",
       .range = kHeightRange, .help = "user's body height in metres (approximate scaling; 0: the model's size)"});
  add({.name = "head_height_m", .field = &at<&DaemonConfig::head_height_m>, .flag = "--head-height-m",
       .range = kHeightRange, .help = "user's standing head height in metres (exact scaling; 0: the model's size)"});
  add({.name = "auto_calibrate", .field = &at<&DaemonConfig::auto_calibrate>, .flag = "!--no-auto-calibrate",
       .help = "do not calibrate the user's size from the head's first still half second (docs/daemon.md, "
               "\"Calibration\")"});
  // The diffusion method's tracker filter and body filter (issue 18 item 4): the filters' own rows,
  // which bodyd-eval's flags share; validate(OneEuroOptions) and validate(BodyFilterOptions) check
  // the values.
  for (const FilterOptionKey& filter : filter_option_keys())
    add({.group = filter.group, .name = filter.name, .field = &filter, .flag = std::string(filter.daemon_flag),
         .help = std::string(filter.help), .doc = filter.group == "filter" ? kTrackerFilter : kBodyFilter});
  add({.name = "offsets", .field = &at<&DaemonConfig::offsets>, .flag = "--offset",
       .help = "device offset ROLE=x,y,z[,qx,qy,qz,qw] (metres; rotation x,y,z,w), repeatable",
       .read = read_offsets, .print = print_offsets});
  add({.name = "log_level", .field = &at<&DaemonConfig::log_level>, .flag = "--log-level",
       .choices = "trace,debug,info,warn,error,critical,off", .help = "trace, debug, info, warn, error, off"});
  return rows;
}

}  // namespace

std::string ConfigKey::full_name() const {
  return group.empty() ? std::string(name) : std::string(group) + "." + std::string(name);
}

std::span<const ConfigKey> config_keys() {
  static const std::vector<ConfigKey> rows = make_rows();
  return rows;
}

std::span<const ConfigGroup> config_groups() {
  static constexpr std::array<ConfigGroup, 3> kGroups{{
      {"sim", "expected an object", "unknown key (see docs/daemon.md, \"sim\")"},
      {"filter", "expected an object like {\"enabled\": true, \"min_cutoff_hz\": 1.0}",
       "unknown key (expected {keys}; docs/daemon.md, \"Tracker filter\")"},
      {"body_filter", "expected an object like {\"enabled\": true, \"min_cutoff_hz\": 2.0}",
       "unknown key (expected {keys}; docs/daemon.md, \"Body filter\")"},
  }};
  return kGroups;
}

const ConfigKey* find_config_key(std::string_view full_name) {
  for (const ConfigKey& row : config_keys())
    if (row.full_name() == full_name) return &row;
  return nullptr;
}

}  // namespace bodyd::daemon
