// The daemon's configuration: every key of the config file (JSON, docs/daemon.md) and every
// command-line flag ends up in DaemonConfig. Flags override the file; the file overrides the
// defaults below. Each key is one row of the config key table (config_keys.h), which names its
// member here, its flag, range and help.
#pragma once

#include "bodyd/inference/one_euro.h"
#include "bodyd/motion/mounting.h"
#include "bodyd/motion/rotation.h"
#include "bodyd/motion/tracker.h"
#include "bodyd/simulators/tracker_sim.h"

#include <nlohmann/json_fwd.hpp>

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace bodyd::daemon {

// Fixed per-device calibration of one role: T_device_joint, the joint's pose in the frame of
// the device that tracks it. A sample's pose becomes T_world_joint = T_world_device *
// T_device_joint (position p + R * offset, rotation R * offset_rotation).
// (The same rigid transform as a mounting's: the conditioner, shared with the evaluation, takes it.)
using DeviceOffset = RigidTransform;

// Where the bundled files are (set at build time to the source tree; see docs/daemon.md).
[[nodiscard]] std::filesystem::path bundled_recording_path();
[[nodiscard]] std::filesystem::path default_model_path();
struct DaemonConfig;
// Empty when reload-model may load `requested`: the configured model file, or a file under
// the models directory (config.models_dir, "" = the default model's directory), compared
// after resolving symlinks and "..". Otherwise why not; never quotes the file's contents.
[[nodiscard]] std::string check_reload_model_path(const std::filesystem::path& requested, const DaemonConfig& config);
[[nodiscard]] std::filesystem::path bundled_skeleton_path();

// The height of the skeleton's Head joint (the base of the skull) as a fraction of body height
// when standing: between chin (0.87) and eye level (0.936) in the usual anthropometric tables
// (Drillis and Contini 1966). An approximation: calibrating from the head is exact.
inline constexpr double kHeadHeightPerStature = 0.90;

// The accepted queue_capacity and queue_max_age_ms (validate_config; the Daemon clamps an
// unchecked configuration to them).
inline constexpr std::size_t kMinQueueCapacity = 16;
inline constexpr std::size_t kMaxQueueCapacity = std::size_t{1} << 20;
inline constexpr double kMaxQueueMaxAgeMs = 60000.0;

struct DaemonConfig {
  // Tracker sources (replay:FILE, sim:FILE.bvh, ...). Empty: the bundled recording, looped
  // (paced) unless exit_at_end.
  std::vector<std::string> sources;
  bool fast = false;          // replays as fast as the pipeline takes them (lossless)
  double replay_speed = 1.0;  // paced replay speed factor
  bool loop = false;          // replays start again at the end
  bool exit_at_end = false;   // exit when every source has finished and the queue is drained
  SimOptions sim;             // for sim: sources

  std::string pub_endpoint = "ipc:///tmp/bodyd/pose";
  std::string control_endpoint = "ipc:///tmp/bodyd/control";  // "" or "none": no control socket
  bool allow_remote = false;
  std::string curve_secret_key_file;  // set: CURVE on both sockets
  std::string curve_allow_dir;        // set: only the client keys in DIR/*.public may connect (ZAP)
  int send_hwm = 1000;                // messages queued per subscriber before ZeroMQ drops
  bool wait_for_subscriber = false;   // start sources when the first subscription arrives
  std::string endpoints_file;         // write the bound endpoints as JSON here (tests, scripts)
  std::string record_trackers_file;   // set: every tracker sample received is written here (tracker log v1)
  // Where the calibration pose's device mountings are kept across restarts (docs/daemon.md,
  // "Device mounting"): read at start when it exists, written by a calibration. "" or "none":
  // nowhere. parse_command_line makes "" the default, $XDG_STATE_HOME/bodyd/mounting.json
  // (~/.local/state/bodyd/mounting.json), whichever way bodyd is started.
  std::string mounting_file;
  bool record_trackers_overwrite = false;  // --overwrite: replace an existing record_trackers_file
  // Outputs besides --pub (docs/outputs.md): specs SCHEME:TARGET?KEY=VALUE&..., e.g.
  // "vrchat:127.0.0.1:9000?slots=hip,feet". The config file's "outputs" list may also hold
  // objects {"type": SCHEME, "target": TARGET, KEY: VALUE...}, converted to this form.
  std::vector<std::string> outputs;

  double rate_hz = 0.0;      // 0: one pose per head sample; > 0: at most this many per second
  std::size_t queue_capacity = 1024;
  // A queued sample that arrived more than this before the newest queued one is dropped
  // (samples_dropped_stale in status): poses lag the trackers by at most about this when the
  // reconstruction cannot keep up (issue 11). 0: never (only a full queue drops).
  double queue_max_age_ms = 100.0;

  std::string method = "diffusion";  // "diffusion" or "ik"
  std::string model_path;            // "": default_model_path()
  // reload-model loads only this model file or files under this directory ("": the
  // directory of default_model_path()); issue 11, docs/control.md.
  std::string models_dir;
  std::string skeleton_path;         // BVH whose skeleton the ik method uses ("": bundled_skeleton_path())
  // Calibration of the user's size. The reconstructors scale by the standing head height (the
  // Head joint's height when standing straight); a body height is converted with
  // kHeadHeightPerStature. At most one of the two may be set; 0: the model's own size.
  double user_height_m = 0.0;        // body height (stature), metres
  double head_height_m = 0.0;        // standing head height, metres (exact)
  // Auto calibration (docs/daemon.md, "Calibration"): the standing head height from the head's
  // first still half second (StandingHeightDetector, inference/calibration.h), unless a height
  // is configured above or the control socket calibrates first; a later calibrate replaces it.
  bool auto_calibrate = true;
  // The diffusion method's One Euro tracker filter (config "filter"; docs/daemon.md, "Tracker
  // filter"). Only enabled, min_cutoff_hz, beta_per_m_s, d_cutoff_hz, rot_min_cutoff_hz,
  // rot_beta_per_rad_s and head_correction_cutoff_hz are configurable; the rest keep the defaults
  // of one_euro.h.
  OneEuroOptions filter;
  // The diffusion method's output-side body filter (config "body_filter"; docs/daemon.md, "Body
  // filter"; one_euro.h BodyFilterOptions): off by default.
  BodyFilterOptions body_filter;
  std::array<std::optional<DeviceOffset>, kRoleCount> offsets{};  // by Role

  std::string log_level = "info";    // trace, debug, info, warn, error, off
};

// Applies the keys of a JSON config object to `config`. Unknown keys and wrong types are
// errors. Returns an empty string, or "source: key: what is wrong".
[[nodiscard]] std::string apply_config_json(const nlohmann::json& json, const std::string& source,
                                            DaemonConfig& config);
// Reads a JSON config file and applies it. Empty, or "file:line:column: what is wrong".
[[nodiscard]] std::string load_config_file(const std::filesystem::path& path, DaemonConfig& config);

// Parses "ROLE=x,y,z" or "ROLE=x,y,z,qx,qy,qz,qw" (--offset). Empty on success.
[[nodiscard]] std::string parse_offset_flag(const std::string& text, DaemonConfig& config);

// The standing head height the configuration asks for (head_height_m, or user_height_m converted);
// 0 when neither is set.
[[nodiscard]] double configured_head_height_m(const DaemonConfig& config);

// Checks values a reader of the file or flags could get wrong (rates, sizes, names). Empty when fine.
[[nodiscard]] std::string validate_config(const DaemonConfig& config);

// Checks that every --source and --output spec is well formed (kind, address, port, options):
// parsed and made, nothing opened, so a typo exits 2 like any bad command line. Empty when fine.
[[nodiscard]] std::string check_specs(const DaemonConfig& config);

// The configuration as JSON (every key; the format load_config_file reads).
[[nodiscard]] nlohmann::json config_to_json(const DaemonConfig& config);

// What the command line asks for besides running.
struct CliResult {
  enum class Action { Run, Exit, GenKeys, PrintConfig, ListDevices } action = Action::Run;
  int exit_code = 0;           // for Action::Exit
  std::string gen_keys_dir;    // for Action::GenKeys
  std::string gen_keys_name = "server";  // for Action::GenKeys: NAME.public, NAME.secret
  std::vector<std::string> notes;  // for the log once it is set up (which config files were read)
};

// Parses the command line (CLI11) into `config`, loading --config FILE first. Prints help
// or errors itself (then Action::Exit).
[[nodiscard]] CliResult parse_command_line(int argc, const char* const* argv, DaemonConfig& config);

}  // namespace bodyd::daemon
