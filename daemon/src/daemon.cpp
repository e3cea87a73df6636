// The daemon's threads and the frame path. The pieces live in their own units:
// outputs (output.h, zmq_publisher, the registry in outputs.cpp), the control socket
// (control_server), the command hand-off (command_channel), statistics (stats), the
// pose -> message conversion (pose_wire), what every sample goes through before the
// reconstructor and the calibrations around it (the body pipeline bodyd-eval shares,
// bodyd/inference/body_pipeline.h; sample_conditioning), the calibration's state
// (calibration_state) and the status reply (status).
#include "bodyd/daemon/daemon.h"

#include "bodyd/base/log_rate.h"
#include "bodyd/base/require.h"

#include "bodyd/daemon/control.h"
#include "bodyd/io/output.h"
#include "bodyd/daemon/sample_queue.h"
#include "bodyd/daemon/tracker_recorder.h"
#include "bodyd/inference/body_pipeline.h"
#include "bodyd/inference/calibration.h"
#include "bodyd/io/open_source.h"
#include "bodyd/protocol/pose_message.h"
#include "calibration_pose_wait.h"
#include "calibration_state.h"
#include "command_channel.h"
#include "control_server.h"
#include "mounting_state.h"
#include "persisted_file.h"
#include "bodyd/io/zmq/pose_wire.h"
#include "sample_conditioning.h"
#include "stats.h"
#include "status.h"
#include "bodyd/io/zmq/zmq_publisher.h"

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <ctime>
#include <map>
#include <mutex>
#include <thread>

namespace bodyd::daemon {

using drivers::monotonic_ns;
using nlohmann::json;

ModelChoice choose_model(const DaemonConfig& config, std::string& warning) {
  ModelChoice choice{config.method, config.model_path.empty() ? default_model_path() : std::filesystem::path(config.model_path)};
  std::error_code ec;
  if (config.method == "diffusion" && config.model_path.empty() && !std::filesystem::exists(choice.model_path, ec)) {
    warning = "the default model " + choice.model_path.string() +
              " does not exist yet: using the ik baseline instead (the shipped models and how to make one: docs/models.md; "
              "or pass --model FILE; --method ik silences this warning)";
    choice.method = "ik";
  }
  return choice;
}

namespace {

constexpr auto kPopTimeout = std::chrono::milliseconds(20);
constexpr std::int64_t kOutputErrorLogPeriodNs = 10'000'000'000;  // one log line per output per 10 s

// config.queue_max_age_ms as the queue takes it (validate_config checks the key's range; a
// Daemon built from an unchecked config gets it clamped to that range, never a throw).
std::chrono::nanoseconds queue_max_age(const DaemonConfig& config) {
  const double ms =
      std::clamp(std::isfinite(config.queue_max_age_ms) ? config.queue_max_age_ms : 0.0, 0.0, kMaxQueueMaxAgeMs);
  return std::chrono::nanoseconds(static_cast<std::int64_t>(ms * 1e6));
}

// One output and what the daemon keeps for it: its rate gate and counters.
struct OutputSlot {
  std::unique_ptr<Output> output;
  bool primary = false;  // the --pub stream: its sends are the pipeline's frames_out and latency
  RateGate gate;
  Counter sent, failed, skipped_by_rate;
  mutable std::mutex error_mutex;
  std::string last_error;           // guarded by error_mutex
  std::int64_t next_error_log_ns = 0;  // reconstruction thread only

  void count_failure(const std::string& error, std::int64_t now_ns) {
    failed.add();
    {
      std::lock_guard lock(error_mutex);
      last_error = error;
    }
    if (now_ns >= next_error_log_ns) {
      spdlog::warn("output {}: send failed: {} ({} failures so far; the next pose is the retry)", output->name(), error,
                   failed.get());
      next_error_log_ns = now_ns + kOutputErrorLogPeriodNs;
    }
  }

  [[nodiscard]] json status() const {
    json j = output->status();
    j["name"] = output->name();
    j["sent"] = sent.get();
    j["send_failed"] = failed.get();
    j["skipped_by_rate"] = skipped_by_rate.get();
    j["rate_hz"] = gate.rate_hz();
    std::lock_guard lock(error_mutex);
    j["last_error"] = last_error;
    return j;
  }
};

}  // namespace

struct Daemon::Impl final : ControlTarget {
  DaemonConfig config;
  ReconstructorFactory factory;
  std::function<void(const FrameTiming&)> observer;

  // Outputs: the --pub pose stream and those of --output, each sent every pose (its rate gate
  // permitting) and handed every skeleton. `pub` is the --pub output's endpoint, for what only
  // it has: the bound address (status, the endpoints file), the CURVE key, its subscriptions
  // and --wait-for-subscriber. Its slot is the `primary` one: its sends are the frames_out,
  // sends_failed and latency statistics (FrameTiming).
  std::vector<std::unique_ptr<OutputSlot>> outputs;
  ZmqPublisher* pub = nullptr;
  ControlServer control;

  SampleQueue queue;
  std::vector<std::unique_ptr<RoleRateSink>> source_sinks;  // one per source, in front of the queue
  std::vector<std::unique_ptr<drivers::TrackerSource>> sources;
  std::unique_ptr<Reconstructor> recon;  // the reconstruction thread's, once started
  std::thread recon_thread;
  bool started = false;
  std::int64_t start_ns = 0;

  std::atomic<bool> stop_flag{false};
  std::atomic<bool> shutdown_requested{false};
  std::atomic<bool> fatal{false};
  std::atomic<bool> drained{false};
  std::atomic<bool> sources_started{false};
  std::mutex wake_mutex;
  std::condition_variable wake;

  PipelineStats stats;
  CommandChannel commands;

  // State shared with the control thread (shared_mutex): what status and the replies say.
  mutable std::mutex shared_mutex;
  ReconstructionSummary summary;
  json recentre_status = json{{"recentred", false}};
  json mounting_status = json::object();
  // The calibration pose's reply, with the mounting to keep in config.mounting_file: the control
  // thread writes the file (it may wait on the disk, and the poses must not), then replies.
  struct PoseResult {
    json reply;
    std::optional<MountingState> to_keep;
  };
  // The calibration poses' results by request id, handed to the control thread (at most two: one
  // answered, not yet collected, and the next one's).
  std::map<std::uint64_t, PoseResult> pose_results;
  // The auto calibration's body-tracker mountings to keep: the main thread (Daemon::run) writes it.
  std::optional<MountingState> auto_to_keep;
  std::uint64_t last_pose_id = 0;  // control thread
  bool offsets_configured = false;

  // Reconstruction-thread state.
  std::uint64_t seq = 0;
  std::int64_t last_pose_t_ns = INT64_MIN;
  RoleArrivals role_arrivals{};
  // status's `trackers`: each role's newest sample (relaxed atomics: written here, read by status()).
  struct RoleSeenAtomic {
    std::atomic<std::int64_t> arrival_ns{INT64_MIN};
    std::atomic<int> source{-1};
    std::atomic<std::uint8_t> flags{0};
  };
  std::array<RoleSeenAtomic, kRoleCount> role_seen;  // OutputFrame::role_arrivals: every sample's, before anything may drop it
  RateGate rate_gate;  // config.rate_hz: how often to reconstruct at all
  BodyPose body;
  BodyPose runtime_body;  // `body` in the runtime's space after a reset (OutputSpace::Runtime)
  protocol::PoseMessage pose_msg;
  std::vector<std::uint8_t> pose_bytes;
  int hips_index = -1;
  bool head_seen = false;  // a valid head sample has arrived
  // Head time going back by more than this restarts the reconstruction (handle_sample).
  static constexpr std::int64_t kTimeBaseRestartNs = 1'000'000'000;
  std::int64_t next_no_head_warning_ns = 0;
  std::atomic<std::uint64_t> loop_iterations{0};

  // What every sample goes through before the reconstructor, and the calibrations around it
  // (body_pipeline.h, shared with bodyd-eval): its mounting, offset and re-centring
  // (`conditioner`, the pipeline's), the auto calibration's height and still second, the
  // calibration pose's application. And the latest valid head sample as the reconstructor got it.
  BodyPipeline pipeline;
  SampleConditioner& conditioner = pipeline.conditioner();
  LatestHead latest_head;

  TrackerRecorder recorder;  // --record-trackers (reconstruction thread once started)

  // Calibration (calibration_state.h). `calibration` is the reconstruction thread's (and
  // start()'s); summary.calibration its copy for the control thread (publish_calibration).
  // The auto calibration (config.auto_calibrate) is the pipeline's, as in bodyd-eval
  // --body-scale: it runs while calibration.auto_waiting() (the two change together).
  CalibrationState calibration;

  // Device mounting (docs/daemon.md "Device mounting"): device poses (PoseFrame::Device) become
  // joint poses through the conditioner's mounting before the per-device offsets. Each role's
  // mounting is the default (from the body reference), or one a calibration pose measured, the
  // auto calibration refined (the head) or config.mounting_file stored (mounting_origin).
  // Reconstruction thread; status reads mounting_status (shared_mutex).
  BodyReference body_reference;
  Mounting default_mount;
  BodyJointsInPose body_joints;  // where body trackers' joints sit in the calibration pose
  MountingOrigins mounting_origin{MountingOrigin::Default, MountingOrigin::Default, MountingOrigin::Default};
  // The calibration pose: started by the control thread (calibrate_pose), fed raw samples and
  // ticked here, its reply handed back through pose_results (shared_mutex); what it measured is
  // applied by the pipeline.
  std::optional<CalibrationPoseWait> pose_wait;
  std::uint64_t pose_id = 0;
  std::array<bool, kRoleCount> body_device_unused{};  // body roles whose device poses were not used (uncalibrated)

  Impl(DaemonConfig c, ReconstructorFactory f)
      : config(std::move(c)),
        factory(std::move(f)),
        queue(std::max(config.queue_capacity, kMinQueueCapacity), queue_max_age(config)),
        rate_gate(config.rate_hz),
        pipeline(config.offsets) {
    for (const auto& o : config.offsets) offsets_configured |= o.has_value();
    if (config.mounting_file == "none") config.mounting_file.clear();  // the calibration is not kept
  }

  // ---------------------------------------------------------------- outputs
  // Creates the --pub output and the --output outputs (not opened yet).
  std::string make_outputs() {
    const OutputEnv env{config};
    std::unique_ptr<ZmqPublisher> primary = make_pub_output(config.pub_endpoint, env);
    pub = primary.get();
    outputs.push_back(std::make_unique<OutputSlot>());
    outputs.back()->output = std::move(primary);
    outputs.back()->primary = true;
    for (const std::string& text : config.outputs) {
      OutputSpec spec;
      std::string error;
      double rate_hz = 0.0;
      if (!parse_output_spec(text, spec, error) || !take_rate_option(spec, rate_hz, error)) return error;
      auto output = make_output(spec, env, error);
      if (!output) return error;
      outputs.push_back(std::make_unique<OutputSlot>());
      outputs.back()->output = std::move(output);
      outputs.back()->gate = RateGate(rate_hz);
    }
    return {};
  }

  std::string open_outputs() {
    for (auto& slot : outputs)
      if (std::string e = slot->output->open(); !e.empty()) return e;
    return {};
  }

  void close_outputs() {
    for (auto& slot : outputs) slot->output->close();
  }

  // ---------------------------------------------------------------- skeleton
  // Reconstruction thread (or start()): refreshes the shared skeleton message from `recon`
  // and hands the skeleton to every output (each ZeroMQ output sends it before the next pose,
  // which names it).
  void refresh_skeleton() {
    protocol::SkeletonMessage m = skeleton_message(recon->skeleton());
    hips_index = recon->skeleton().find("Hips");
    std::vector<std::uint8_t> bytes;
    // Both reconstructors take only skeletons of the bundled joints, which encode: a failure is a bug.
    const protocol::Status encoded = protocol::encode_skeleton(m, bytes);
    BODYD_REQUIRE(encoded.ok(), "the reconstructor's skeleton cannot be encoded: " + encoded.error);
    {
      std::lock_guard lock(shared_mutex);
      summary.skeleton = std::move(m);
      summary.method = std::string(recon->name());
      summary.head_height_m = recon->head_height_m();
    }
    for (auto& slot : outputs) slot->output->set_skeleton(recon->skeleton(), bytes);
  }

  // ---------------------------------------------------------------- reconstruction thread
  void handle_sample(drivers::SourceSample& in) {
    TrackerSample& s = in.sample;
    role_arrivals[static_cast<std::size_t>(s.role)] = {in.arrival_ns, in.source_index};
    // The raw sample (before mounting, offsets, re-centring) to the calibrations, body trackers'
    // device poses included: the calibration pose measures their mountings.
    feed_pose_calibrators(s, in.arrival_ns);
    {
      RoleSeenAtomic& seen = role_seen[static_cast<std::size_t>(s.role)];
      seen.flags.store(static_cast<std::uint8_t>((s.valid ? RoleSeen::kValid : 0) | (s.has_position ? RoleSeen::kPosition : 0) |
                                                 (conditioner.uses(s) ? RoleSeen::kUsed : 0)),
                       std::memory_order_relaxed);
      seen.source.store(static_cast<int>(in.source_index), std::memory_order_relaxed);
      seen.arrival_ns.store(in.arrival_ns, std::memory_order_relaxed);
    }
    if (!conditioner.uses(s)) {
      // A body tracker's device pose before its mounting is measured (a calibration pose, the
      // auto calibration's still second, or the mounting file): its strap sits a few centimetres
      // off the joint and turned any way, and a device pose is never used through an unknown
      // offset at full weight. Joint poses (frames=joint, logs, the simulator) are used.
      stats.body_device_samples_ignored.add();
      body_device_unused[static_cast<std::size_t>(s.role)] = true;
      if (const std::uint64_t n = stats.body_device_samples_ignored.get(); log_occurrence(n))
        spdlog::info("{} sample (a body tracker's device pose) not used: its mounting is not calibrated yet: stand in "
                     "the calibration pose (`bodyd-ctl calibrate --pose`), or give its source ?frames=joint if it "
                     "sends the joint's own pose (docs/conventions.md, \"Tracker roles\"; logged at the 1st, 2nd, 4th, 8th...)",
                     role_name(s.role));
      return;
    }
    const TrackerSample as_received = s;  // before the mounting and offset (OutputFrame::head_as_received)
    const bool first_device_pose = s.frame == PoseFrame::Device && !conditioner.device_frames_seen(s.role);
    conditioner.condition(s);
    // status's device_frames per role (issue 43 item 13: after a restart with a kept mounting it
    // said "no device poses yet" for good, nothing else republishing it); once per role.
    if (first_device_pose) publish_mounting_status();
    // The log reader ends with the same normalisation (sample_conditioning.h), so a replay of the
    // recording is bit-identical (tracker_recorder.h).
    if (recorder.is_open()) recorder.record(s);
    SampleConditioner::finish(s);
    if (s.role == Role::Head && last_pose_t_ns != INT64_MIN && s.t_ns < last_pose_t_ns - kTimeBaseRestartNs) {
      // Head time went far back: a replay's time base started over (a loop at the int64 limit,
      // issue 11) or a source restarted. The reconstruction starts over instead of waiting,
      // silently, until time passes the last pose again.
      spdlog::warn("head time went back by {:.3f} s: the reconstruction starts over", (last_pose_t_ns - s.t_ns) * 1e-9);
      stats.time_restarts.add();
      recon->reset();
      pipeline.time_restarted();  // the auto height calibration's times went back too
      last_pose_t_ns = INT64_MIN;
      rate_gate = RateGate(rate_gate.rate_hz());
      for (auto& slot : outputs) slot->gate = RateGate(slot->gate.rate_hz());
    }
    if (s.role == Role::Head && s.valid) latest_head.update(s, in.arrival_ns);
    if (std::optional<AutoHeightEvent> h = pipeline.before_push(s, *recon)) report_auto_height(*h, s.t_ns);
    const std::int64_t refused_before = recon->refused_samples();
    recon->push(s);
    if (recon->refused_samples() != refused_before) stats.samples_refused.add();
    stats.samples_in.add();
    stats.role_samples[static_cast<int>(s.role)].add();
    if (s.role != Role::Head) return;
    if (!head_seen && s.valid) {  // an invalid head gives no pose (issue 11)
      head_seen = true;
      spdlog::info("first valid head sample received; publishing poses");
    }
    if (s.t_ns <= last_pose_t_ns) return;  // a pose for this time was already sent
    if (!rate_gate.due(s.t_ns)) {
      stats.skipped_by_rate.add();
      return;
    }
    FrameTiming timing;
    timing.arrival_ns = in.arrival_ns;
    timing.t_ns = s.t_ns;
    timing.reconstruct_start_ns = monotonic_ns();
    const bool ok = recon->reconstruct(s.t_ns, body);
    timing.reconstruct_end_ns = monotonic_ns();
    if (!ok) {
      stats.not_ready.add();
      return;
    }
    last_pose_t_ns = s.t_ns;
    stats.reconstruct.add(timing.reconstruct_end_ns - timing.reconstruct_start_ns);

    PoseMessageContext context;
    context.seq = seq;
    context.t_ns = s.t_ns;
    context.root_joint = hips_index;
    context.offsets_configured = offsets_configured;
    {
      std::lock_guard lock(shared_mutex);
      context.height_calibrated = summary.calibration.height_calibrated();
      context.skeleton_id = summary.skeleton.skeleton_id;
    }
    fill_pose_message(body, context, pose_msg);
    pose_msg.publish_t_ns = monotonic_ns();
    // The skeleton encoded, so only a non-finite or non-unit value can fail here: a reconstructor bug.
    const protocol::Status encoded = protocol::encode_pose(pose_msg, pose_bytes);
    BODYD_REQUIRE(encoded.ok(), fmt::format("the pose at t_ns={} cannot be encoded: {}", s.t_ns, encoded.error));

    // Each output's space (output.h, OutputSpace): the body in the runtime's space is made once,
    // when an output due now publishes in it and a reset has moved the user's space away from it.
    bool runtime_body_made = !conditioner.recentred();
    const OutputFrame user_frame{seq, s.t_ns, in.arrival_ns, body, recon->skeleton(), pose_msg, pose_bytes, as_received,
                                 role_arrivals};
    const OutputFrame runtime_frame{seq,        s.t_ns,     in.arrival_ns, conditioner.recentred() ? runtime_body : body,
                                    recon->skeleton(), pose_msg, pose_bytes, as_received, role_arrivals};
    std::string error;
    for (auto& slot_ptr : outputs) {
      OutputSlot& slot = *slot_ptr;
      if (!slot.gate.due(s.t_ns)) {
        slot.skipped_by_rate.add();
        continue;
      }
      const bool runtime = slot.output->space() == OutputSpace::Runtime;
      if (runtime && !runtime_body_made) {
        conditioner.to_runtime_space(body, runtime_body);
        runtime_body_made = true;
      }
      const bool sent = slot.output->send(runtime ? runtime_frame : user_frame, error);
      if (sent) slot.sent.add();
      else slot.count_failure(error, monotonic_ns());
      if (slot.primary) {
        timing.sent = sent;
        timing.published_ns = monotonic_ns();
        if (sent) stats.frames_out.add();
        else stats.sends_failed.add();
      }
    }
    timing.outputs_sent_ns = monotonic_ns();
    timing.seq = seq++;
    stats.latency.add(timing.published_ns - timing.arrival_ns);
    if (observer) observer(timing);
  }

  // ---------------------------------------------------------------- calibration
  // Copies the calibration state for the control thread.
  void publish_calibration() {
    std::lock_guard lock(shared_mutex);
    summary.calibration = calibration;
  }

  // Reconstruction thread: the raw sample (before mounting, offsets, re-centring) to the
  // calibration pose in progress and to the auto calibration's still second (the pipeline's).
  void feed_pose_calibrators(const TrackerSample& raw, std::int64_t arrival_ns) {
    if (pose_wait)
      if (std::optional<CalibrationPoseWait::Outcome> o = pose_wait->push(raw, arrival_ns))
        finish_pose_wait(std::move(*o));
    const RawSampleEvents events = pipeline.observe_raw(raw, arrival_ns, *recon);
    if (events.still_second) report_still_second(*events.still_second);
    if (events.still_second_expired) {
      if (pipeline.still_second_refines_head())
        spdlog::info("auto calibration: no still second of the headset and controllers in the first {} s: the "
                     "default head mounting stays (`bodyd-ctl calibrate --pose` measures it)",
                     BodyPipeline::kStillSecondWindowNs / 1'000'000'000);
      if (any_body_tracker_unmeasured())
        spdlog::info("auto calibration: no still second in the first {} s: body trackers not measured yet stay "
                     "unused until `bodyd-ctl calibrate --pose`",
                     BodyPipeline::kStillSecondWindowNs / 1'000'000'000);
    }
  }

  // Reconstruction thread: ends the calibration pose's wait with its reply.
  void finish_pose_wait(CalibrationPoseWait::Outcome outcome) {
    pose_wait.reset();
    PoseResult result;
    if (outcome.calibration) {
      result = apply_pose_calibration(*outcome.calibration);
    } else {
      spdlog::info("calibration pose refused: {}", outcome.refusal);
      result.reply = control_error("calibrate from pose: " + outcome.refusal);
    }
    std::lock_guard lock(shared_mutex);
    pose_results[pose_id] = std::move(result);
  }

  // calibrate --from-head: a standing head sways at a few cm/s; a slow walk moves at 0.5 m/s.
  static constexpr double kMaxStandingHeadSpeedMS = 0.2;

  // What the auto calibration's still second applied (body_pipeline.h): the body trackers it
  // measured (without it an uncalibrated body tracker is not used at all; kept in the mounting
  // file) and the headset's refinement, kept only when plausible (within
  // BodyPipeline::kMaxStillHeadChangeDeg of the default: a user who stands still looking down at
  // a menu must not get a bent body).
  void report_still_second(const StillSecondEvent& e) {
    const PoseCalibration& c = e.calibration;
    std::string measured;
    for (Role r : kRoles) {
      const auto i = static_cast<std::size_t>(r);
      if (!e.body_measured[i]) continue;
      mounting_origin[i] = MountingOrigin::Auto;
      measured += fmt::format("{}{} ({:.0f} cm from its joint in the pose)", measured.empty() ? "" : ", ", role_name(r), c.offset_cm[i]);
    }
    if (!measured.empty()) {
      spdlog::info("auto calibration: body trackers measured from a still second: {}", measured);
      recorder.comment(fmt::format("t_ns {}: mounting {} (auto)", c.t_ns, mounting_text(e.mounting_after_body)));
      if (!config.mounting_file.empty()) {
        MountingState st = mounting_state_to_keep(e.mounting_after_body);
        std::lock_guard lock(shared_mutex);
        auto_to_keep = std::move(st);
      }
    }
    switch (e.head) {
      case StillSecondEvent::Head::Kept:
        break;
      case StillSecondEvent::Head::TooFar:
        spdlog::info("auto calibration: the headset's still second is {:.1f} deg from looking ahead (looking up or down?): "
                     "the default head mounting stays (`bodyd-ctl calibrate --pose` measures it)",
                     e.head_change_deg);
        break;
      case StillSecondEvent::Head::Refined:
        mounting_origin[0] = MountingOrigin::Auto;
        spdlog::info("auto calibration: the headset sits {:.1f} deg from the default on the head (from a still second)",
                     e.head_change_deg);
        recorder.comment(
            fmt::format("t_ns {}: mounting head {} (auto)", c.t_ns, transform_text(conditioner.mounting().T_device_joint[0])));
        break;
    }
    if (!measured.empty() || e.head == StillSecondEvent::Head::Refined) publish_mounting_status();
  }

  // Main thread: writes what the auto calibration measured to the mounting file, off the
  // reconstruction thread (the disk may wait).
  void keep_auto_mounting() {
    std::optional<MountingState> st;
    {
      std::lock_guard lock(shared_mutex);
      st.swap(auto_to_keep);
    }
    if (!st) return;
    if (std::string e = write_mounting_state(config.mounting_file, *st); !e.empty())
      spdlog::warn("auto calibration: {} (the body trackers' mountings hold until bodyd stops)", e);
  }

  // A body tracker has sent device poses that cannot be used until its mounting is measured.
  [[nodiscard]] bool any_body_tracker_unmeasured() const {
    for (Role r : kRoles)
      if (!is_xr_role(r) && body_device_unused[static_cast<int>(r)] && mounting_origin[static_cast<int>(r)] == MountingOrigin::Default)
        return true;
    return false;
  }

  // What the mounting file is to keep now, with `mounting`.
  MountingState mounting_state_to_keep(const Mounting& mounting) {
    MountingState st;
    st.mounting = mounting;
    for (Role r : kRoles) st.measured[static_cast<int>(r)] = mounting_origin[static_cast<int>(r)] != MountingOrigin::Default;
    st.head_height_m = calibration.height_calibrated() ? recon->head_height_m() : 0.0;
    st.calibrated = utc_now();
    return st;
  }

  // Applies a calibration pose's result through the pipeline (mountings, a fresh history, the
  // height) and says so. Returns the control reply and what the mounting file is to keep (the
  // control thread writes it).
  PoseResult apply_pose_calibration(const PoseCalibration& c) {
    const std::string height_error = pipeline.apply_calibration_pose(c, *recon).height_error;
    json roles = json::object();
    for (Role r : kRoles) {
      const int i = static_cast<int>(r);
      if (!c.measured[i]) continue;
      mounting_origin[i] = MountingOrigin::Pose;
      if (!is_xr_role(r)) {
        // A body tracker has no default to compare with: how far it sits from its joint.
        roles[std::string(role_name(r))] = {{"offset_cm", 100.0 * c.mounting.T_device_joint[i].position_m.norm()},
                                            {"from_pose_joint_cm", c.offset_cm[i]},
                                            {"sd_deg", c.rotation_sd_deg[i]},
                                            {"motion_deg", c.motion_deg[i]}};
        continue;
      }
      const MountingDifference d = mounting_difference(conditioner.mounting().T_device_joint[i], default_mount.T_device_joint[i]);
      roles[std::string(role_name(r))] = {{"from_default_deg", d.angle_deg},
                                          {"from_default_cm", d.position_cm},
                                          {"sd_deg", c.rotation_sd_deg[i]},
                                          {"motion_deg", c.motion_deg[i]}};
    }
    if (height_error.empty()) {
      calibration.manual();
      publish_calibration();
    }
    refresh_skeleton();
    publish_mounting_status();
    const Mounting& mounting = conditioner.mounting();
    spdlog::info("calibrated from the calibration pose: standing head height {:.3f} m{}; mounting {}", recon->head_height_m(),
                 height_error.empty() ? "" : " (the height was refused: " + height_error + ")", mounting_text(mounting));
    recorder.comment(fmt::format("t_ns {}: calibrate pose head_height_m {} mounting {}", c.t_ns, recon->head_height_m(),
                                 mounting_text(mounting)));
    PoseResult result;
    if (!config.mounting_file.empty()) {
      MountingState& st = result.to_keep.emplace(mounting_state_to_keep(mounting));
      st.head_height_m = height_error.empty() ? recon->head_height_m() : 0.0;
    }
    std::lock_guard lock(shared_mutex);
    json reply{{"ok", height_error.empty()},
               {"device_frames", c.device_frames},
               {"eye_offset_sd_cm", c.eye_offset_sd_cm},
               {"roles", roles},
               {"mounting", mounting_status}};
    summary_json(summary, reply);
    if (!height_error.empty()) reply["error"] = "calibrate from pose: " + height_error;
    if (!c.device_frames)
      reply["note"] = "the sources deliver joint poses: there is no device mounting to learn, only the height";
    if (!config.mounting_file.empty()) reply["mounting_file"] = config.mounting_file;
    result.reply = std::move(reply);
    return result;
  }

  static std::string utc_now() {
    const std::time_t now = std::time(nullptr);
    char text[32] = {};
    std::strftime(text, sizeof(text), "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
    return text;
  }

  // Reconstruction thread (or start()): the mounting as status shows it.
  void publish_mounting_status() {
    json m = mounting_status_json(conditioner.mounting(), default_mount, mounting_origin, conditioner, config.mounting_file);
    std::lock_guard lock(shared_mutex);
    mounting_status = std::move(m);
  }

  // What the auto height calibration did (the pipeline applies the height before the head sample
  // at `t_ns` is pushed, so the sample counts at the new size, as in bodyd-eval).
  void report_auto_height(const AutoHeightEvent& e, std::int64_t t_ns) {
    switch (e.outcome) {
      case AutoHeightEvent::Outcome::NotFound:
        calibration.auto_refused();
        publish_calibration();
        spdlog::warn("auto calibration: no plausible standing head height in the first {:.1f} s (sitting?): the "
                     "model's size stays; stand up and run `bodyd-ctl calibrate --from-head`",
                     StandingHeightOptions{}.fallback_after_s);
        return;
      case AutoHeightEvent::Outcome::Refused:
        calibration.auto_refused();
        publish_calibration();
        spdlog::warn("auto calibration refused: {}", e.error);
        return;
      case AutoHeightEvent::Outcome::Applied:
        break;
    }
    const StandingHeight& h = e.height;
    calibration.auto_measured(h.fallback);
    publish_calibration();
    refresh_skeleton();
    const std::string how =
        h.fallback ? fmt::format("no still half second: the head's {:.0f}th percentile height {:.3f} m over the first {:.1f} s",
                                 StandingHeightOptions{}.fallback_percentile, h.measured_m,
                                 StandingHeightOptions{}.fallback_after_s)
                   : fmt::format("the head held still at {:.3f} m", h.measured_m);
    spdlog::info("auto calibrated: standing head height {:.3f} m ({})", recon->head_height_m(), how);
    recorder.comment(fmt::format("t_ns {}: calibrate head_height_m {} (auto: {})", t_ns, recon->head_height_m(), how));
  }

  // The control socket set the standing head height (`cleared`: back to the model's own). A
  // calibration from the control socket replaces the auto one (and stops it if it is waiting);
  // the skeleton is published again, the log says so (`what`, then the height) and the
  // recording notes it.
  void control_head_height_applied(std::string_view what, bool cleared = false) {
    if (cleared) {
      calibration.cleared();
    } else {
      calibration.manual();
      pipeline.stop_auto_height();
    }
    publish_calibration();
    refresh_skeleton();
    spdlog::info("{} {:.3f} m", what, recon->head_height_m());
    recorder.comment(fmt::format("t_ns {}: calibrate head_height_m {}", latest_head.sample().t_ns, recon->head_height_m()));
  }

  json apply_command(Command& c) {
    const std::int64_t now_ns = monotonic_ns();
    switch (c.kind) {
      case Command::Kind::Height: {
        recon->set_head_height_m(c.height_m);
        control_head_height_applied("calibrated: standing head height", !(c.height_m > 0.0));
        break;
      }
      case Command::Kind::FromHead: {
        if (!latest_head.fresh(now_ns))
          return control_error("no valid head sample in the last 2 s: wear the headset, stand up straight, and retry");
        // The Head joint's height now, as a standing height: the same correction and checks as
        // the auto calibration and bodyd-eval (inference/calibration.h).
        // Walking or swaying: the height would be a step's, not the standing height (issue 16).
        if (latest_head.speed_m_s() > kMaxStandingHeadSpeedMS)
          return control_error(fmt::format(
              "calibrate from head: the head is moving at {:.2f} m/s: stand still (up straight, looking ahead) and retry",
              latest_head.speed_m_s()));
        const double measured_m = latest_head.sample().position_m.y();
        if (std::string e = calibrate_from_head_height(*recon, standing_height_from_head(measured_m, StandingHeightOptions{}));
            !e.empty())
          return control_error(e);
        control_head_height_applied("calibrated from the standing head height:");
        break;
      }
      case Command::Kind::Recentre: {
        if (!latest_head.fresh(now_ns))
          return control_error("reset: no valid head sample in the last 2 s: wear the headset (is it tracking?) and retry");
        const Recentring r = conditioner.recentre_on(latest_head.sample());
        recon->reset();  // the space jumped: start a fresh history
        {
          json st = recentre_status_json(conditioner);
          std::lock_guard lock(shared_mutex);
          recentre_status = std::move(st);
        }
        recorder.comment(fmt::format("t_ns {}: reset (re-centred: turned by {:.3f} deg, origin x {:.4f} z {:.4f} m)",
                                     latest_head.sample().t_ns, r.heading_deg, r.origin_m.x(), r.origin_m.z()));
        spdlog::info("re-centred: facing {:.1f} deg from forward, at x {:.3f} z {:.3f} m: that is now forward and the origin",
                     r.heading_deg, r.origin_m.x(), r.origin_m.z());
        return json{{"ok", true},
                    {"heading_deg", r.heading_deg},
                    {"origin_m", {r.origin_m.x(), r.origin_m.z()}},
                    {"recentred", true}};
      }
      case Command::Kind::PoseBegin: {
        if (pose_wait)
          return control_error(
              "calibrate from pose: a calibration pose is already waiting (another request started it): wait for its "
              "answer, then retry");
        if (!latest_head.fresh(now_ns))
          return control_error(
              "calibrate from pose: no valid head sample in the last 2 s: wear the headset (is it tracking?) and retry");
        pose_wait.emplace(body_reference, default_mount, now_ns, c.timeout_s, body_joints);
        pose_id = c.pose_id;
        spdlog::info("calibration pose: waiting up to {:.0f} s for a still second (stand straight, look ahead, arms "
                     "relaxed at the sides)",
                     c.timeout_s);
        return json{{"ok", true}};
      }
      case Command::Kind::Swap: {
        {
          std::lock_guard lock(shared_mutex);
          summary.model_path = c.model_path;
        }
        if (calibration.height_calibrated()) c.recon->set_head_height_m(recon->head_height_m());
        recon = std::move(c.recon);
        last_pose_t_ns = INT64_MIN;
        refresh_skeleton();
        spdlog::info("model reloaded: {} ({})", recon->name(), c.model_path);
        recorder.comment(fmt::format("t_ns {}: reload-model {} {}", latest_head.sample().t_ns, recon->name(), c.model_path));
        break;
      }
    }
    std::lock_guard lock(shared_mutex);
    json reply{{"ok", true}, {"method", summary.method}};
    summary_json(summary, reply);
    return reply;
  }

  void process_command() {
    commands.serve([this](Command& c) { return apply_command(c); });
  }

  bool start_sources() {
    for (std::size_t i = 0; i < sources.size(); ++i) {
      if (std::string e = sources[i]->start(*source_sinks[i], static_cast<std::uint16_t>(i)); !e.empty()) {
        spdlog::critical("{}", e);
        return false;
      }
    }
    sources_started.store(true);
    return true;
  }

  bool all_sources_finished() const {
    for (const auto& s : sources)
      if (!s->status().finished) return false;
    return true;
  }

  std::string source_names() const {
    std::string names;
    for (const auto& s : sources) names += (names.empty() ? "" : ", ") + s->name();
    return names;
  }

  void warn_if_no_head(std::int64_t now_ns) {
    if (head_seen || now_ns < next_no_head_warning_ns) return;
    if (next_no_head_warning_ns != 0)
      spdlog::warn("no trackers: waiting for a valid head sample from {} (is the headset on and tracking? "
                   "check the source with `bodyd --source ... --log-level debug`)",
                   source_names());
    next_no_head_warning_ns = now_ns + (next_no_head_warning_ns == 0 ? 3'000'000'000LL : 30'000'000'000LL);
  }

  void poll_outputs(std::int64_t now_ns, const Output* except = nullptr) {
    for (auto& slot : outputs)
      if (slot->output.get() != except) slot->output->poll(now_ns);
  }

  void reconstruction_loop() {
    if (config.wait_for_subscriber) {
      spdlog::info("waiting for a subscriber on {} before starting the sources", pub->bound());
      while (!stop_flag.load()) {
        loop_iterations.fetch_add(1, std::memory_order_relaxed);
        process_command();
        // The other outputs meanwhile as always (a ZeroMQ output sends its skeleton to a
        // subscriber that is already there); --pub's subscriptions are what this waits for.
        poll_outputs(monotonic_ns(), pub);
        if (pub->wait_for_subscription(50, monotonic_ns())) break;
      }
      if (stop_flag.load()) return;
    }
    poll_outputs(monotonic_ns());  // the skeleton, before the sources start
    if (!start_sources()) {
      fatal.store(true);
      notify();
      return;
    }
    next_no_head_warning_ns = 0;
    drivers::SourceSample sample;
    while (!stop_flag.load(std::memory_order_relaxed)) {
      loop_iterations.fetch_add(1, std::memory_order_relaxed);
      poll_outputs(monotonic_ns());
      process_command();
      if (queue.pop(sample, kPopTimeout)) {
        handle_sample(sample);
      } else if (!drained.load() && all_sources_finished() && queue.size() == 0) {
        drained.store(true);
        spdlog::info("every source has finished; {} poses published", seq);
        notify();
      }
      const std::int64_t now_ns = monotonic_ns();
      if (pose_wait)
        if (std::optional<CalibrationPoseWait::Outcome> o = pose_wait->tick(now_ns, queue.size() == 0))
          finish_pose_wait(std::move(*o));
      warn_if_no_head(now_ns);
      recorder.poll(now_ns);  // the recording reaches the file at least every half second
    }
  }

  void notify() {
    std::lock_guard lock(wake_mutex);
    wake.notify_all();
  }

  // ---------------------------------------------------------------- ControlTarget (control thread)
  json status() override {
    StatusSnapshot s;
    s.uptime_s = static_cast<double>(drivers::monotonic_ns() - start_ns) / 1e9;
    s.now_ns = drivers::monotonic_ns();
    for (std::size_t r = 0; r < kRoleCount; ++r)
      s.trackers[r] = {role_seen[r].arrival_ns.load(std::memory_order_relaxed), role_seen[r].source.load(std::memory_order_relaxed),
                       role_seen[r].flags.load(std::memory_order_relaxed)};
    {
      std::lock_guard lock(shared_mutex);
      s.summary = summary;
      s.recentre = recentre_status;
      s.mounting = mounting_status;
    }
    s.offsets_configured = offsets_configured;
    s.record_trackers_file = config.record_trackers_file;
    for (const auto& source : sources) s.sources.push_back(source->status());
    const std::int64_t now_ns = drivers::monotonic_ns();
    for (std::size_t i = 0; i < sources.size(); ++i)
      s.source_rates_hz_by_role.push_back(source_sinks[i]->rate_hz_by_role(now_ns));
    s.sources_started = sources_started.load();
    s.samples_dropped = queue.dropped();
    s.samples_dropped_stale = queue.dropped_stale();
    s.queue_depth = queue.size();
    s.queue_capacity = queue.capacity();
    if (pub) {
      s.pub = pub->bound();
      s.pub_subscriptions = pub->subscriptions();
      s.pub_skeleton_sends_failed = pub->skeleton_sends_failed();
      s.curve = !pub->curve_public_key().empty();
    }
    s.control = control.bound();
    s.rate_hz = config.rate_hz;
    for (const auto& slot : outputs) s.outputs.push_back(slot->status());
    return status_json(s, stats);
  }

  json skeleton() override {
    std::lock_guard lock(shared_mutex);
    return skeleton_reply(summary.skeleton, summary.head_height_m);
  }

  json calibrate_height(double height_m) override {
    Command c;
    c.kind = Command::Kind::Height;
    c.height_m = height_m;
    return commands.run(std::move(c));
  }

  json calibrate_from_head() override {
    Command c;
    c.kind = Command::Kind::FromHead;
    return commands.run(std::move(c));
  }

  json reload_model(const std::optional<std::string>& path) override {
    std::string current;
    {
      std::lock_guard lock(shared_mutex);
      current = summary.model_path;
    }
    ModelChoice choice{config.method, path ? std::filesystem::path(*path)
                                           : (current.empty() ? default_model_path() : std::filesystem::path(current))};
    if (path) {
      // Only the configured model or files under the models directory (issue 11): the control
      // socket must not become a way to read, or probe, any file the daemon can open.
      if (std::string e = check_reload_model_path(*path, config); !e.empty()) return control_error("reload-model: " + e);
      choice.method = "diffusion";  // a model file is for the diffusion method
    }
    std::string error;
    std::unique_ptr<Reconstructor> next = factory(choice, error);
    if (!next) return control_error("reload-model: " + error);
    Command c;
    c.kind = Command::Kind::Swap;
    c.recon = std::move(next);
    c.model_path = choice.method == "ik" ? std::string() : choice.model_path.string();
    return commands.run(std::move(c));
  }

  json recentre() override {
    Command c;
    c.kind = Command::Kind::Recentre;
    return commands.run(std::move(c));
  }

  // Control thread: starts the calibration pose on the reconstruction thread; the reply comes
  // later, when the reconstruction thread ends the wait (the still second, a refusal, the
  // timeout), and the control socket answers other requests meanwhile.
  ControlReply calibrate_pose(double timeout_s) override {
    Command c;
    c.kind = Command::Kind::PoseBegin;
    c.timeout_s = timeout_s;
    c.pose_id = ++last_pose_id;
    const std::uint64_t id = c.pose_id;
    json started = commands.run(std::move(c));
    if (!started.value("ok", false)) return started;
    // The reconstruction thread answers by the timeout; this is for a thread that stopped.
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s + 2.0);
    return ControlReply(LaterReply([this, id, give_up]() -> std::optional<json> {
      if (std::optional<json> r = take_pose_result(id)) return r;
      if (stop_flag.load()) return control_error("calibrate from pose: bodyd is stopping");
      if (std::chrono::steady_clock::now() > give_up)
        return control_error("calibrate from pose: the reconstruction thread did not answer (a bug: see bodyd's log)");
      return std::nullopt;
    }));
  }

  // Control thread: the calibration pose's reply once the reconstruction thread has handed it
  // over, after writing the mounting it measured to the mounting file.
  std::optional<json> take_pose_result(std::uint64_t id) {
    std::optional<PoseResult> result;
    {
      std::lock_guard lock(shared_mutex);
      auto it = pose_results.find(id);
      if (it == pose_results.end()) return std::nullopt;
      result = std::move(it->second);
      pose_results.erase(it);
    }
    if (result->to_keep) {
      if (std::string e = write_mounting_state(config.mounting_file, *result->to_keep); !e.empty()) {
        spdlog::warn("calibration pose: {} (the calibration holds until bodyd stops)", e);
        result->reply["mounting_file_error"] = std::move(e);
      }
    }
    return std::move(result->reply);
  }

  json shutdown() override {
    spdlog::info("shutdown requested on the control socket");
    shutdown_requested.store(true);
    notify();
    return json{{"ok", true}};
  }
};

Daemon::Daemon(DaemonConfig config, ReconstructorFactory factory)
    : impl_(std::make_unique<Impl>(std::move(config), std::move(factory))) {}

Daemon::~Daemon() { stop(); }

void Daemon::set_frame_observer(std::function<void(const FrameTiming&)> observer) { impl_->observer = std::move(observer); }

std::string Daemon::start() {
  Impl& d = *impl_;
  if (d.started) return "bodyd: already started";
  d.start_ns = monotonic_ns();

  // The outputs first: a bad --output spec is reported before anything slow happens.
  if (std::string e = d.make_outputs(); !e.empty()) return e;

  // The reconstructor.
  std::string warning;
  const ModelChoice choice = choose_model(d.config, warning);
  if (!warning.empty()) spdlog::warn("{}", warning);
  std::string error;
  d.recon = d.factory(choice, error);
  if (!d.recon) return error.empty() ? "cannot create the " + choice.method + " reconstructor" : error;
  if (const double head_height_m = configured_head_height_m(d.config); head_height_m > 0.0) {
    d.recon->set_head_height_m(head_height_m);
    d.calibration.start(true, d.config.auto_calibrate);
  } else {
    d.calibration.start(false, d.config.auto_calibrate);
  }
  if (d.calibration.auto_waiting()) {
    spdlog::info("auto calibration: the user's size from the head's first still half second (off: --no-auto-calibrate)");
  }
  d.summary.model_path = choice.method == "ik" ? std::string() : choice.model_path.string();

  // Device mounting: the defaults from the body reference, then what a calibration pose stored.
  try {
    d.body_reference = read_body_reference(find_body_reference());
  } catch (const BodyReferenceError& e) {
    return std::string("device mounting: ") + e.what();
  }
  d.default_mount = default_mounting(d.body_reference);
  try {
    d.body_joints = body_joints_in_pose(d.recon->skeleton());
  } catch (const UserError& e) {
    // A skeleton without the reference's joints (a reduced test rig): no body tracker can be
    // placed in the pose, so none is measured and their device poses stay unused.
    spdlog::info("body trackers' mountings cannot be measured with this skeleton ({})", e.what());
  }
  d.conditioner.set_default_mounting(d.default_mount);
  if (!d.config.mounting_file.empty()) {
    std::string merror;
    if (std::optional<MountingState> st =
            read_mounting_state(d.config.mounting_file, d.default_mount, PoseCalibrationOptions{}, merror)) {
      for (const std::string& refused : st->refused) spdlog::warn("{}", refused);
      for (Role r : kRoles) {
        const int i = static_cast<int>(r);
        if (!st->measured[i]) continue;
        d.conditioner.set_mounting(r, st->mounting.T_device_joint[i]);
        d.mounting_origin[i] = MountingOrigin::File;
      }
      spdlog::info("device mounting from {} (calibrated {}): {}", d.config.mounting_file, st->calibrated,
                   mounting_text(d.conditioner.mounting()));
      // The user measured in a calibration pose wins over a configured size (issue 43 item 13:
      // a user_height_m in the config silently replaced it), and the log says so.
      if (st->head_height_m > 0.0) {
        if (d.calibration.source() == HeightSource::Config) {
          const std::string configured =
              d.config.head_height_m > 0.0
                  ? fmt::format("head_height_m {}", d.config.head_height_m)
                  : fmt::format("user_height_m {} (head height {:.3f} m)", d.config.user_height_m,
                                configured_head_height_m(d.config));
          spdlog::info("calibration: the measured head height {:.3f} m (mounting file {}, calibrated {}) is used instead "
                       "of the configured {} (with --mounting-file none the configured one is used)",
                       st->head_height_m, d.config.mounting_file, st->calibrated.empty() ? "at an unknown time" : st->calibrated,
                       configured);
        }
        d.recon->set_head_height_m(st->head_height_m);
        d.calibration.from_file();
      }
    } else if (!merror.empty()) {
      spdlog::warn("{}: the default device mounting is used", merror);
    }
  }
  // The auto calibration (auto_calibrate on): the user's size from the head's first still half
  // second, unless a height is known; and the first still second of the session refines the
  // headset's default mounting (with the auto height calibration) and measures the body
  // trackers not measured yet.
  if (d.calibration.auto_waiting()) d.pipeline.start_auto_height();
  if (d.config.auto_calibrate)
    d.pipeline.start_still_second(d.body_reference, d.default_mount, d.body_joints,
                                  d.calibration.auto_waiting() && d.mounting_origin[0] == MountingOrigin::Default);
  d.publish_calibration();
  d.publish_mounting_status();
  d.refresh_skeleton();
  spdlog::info("reconstruction: {}{}, standing head height {:.3f} m, skeleton {} joints (id {:#010x})", d.recon->name(),
               d.summary.model_path.empty() ? "" : " (" + d.summary.model_path + ")", d.recon->head_height_m(),
               d.recon->skeleton().size(), d.summary.skeleton.skeleton_id);

  // The sources.
  std::vector<std::string> specs = d.config.sources;
  drivers::SourceOptions options;
  options.replay.paced = !d.config.fast;
  options.replay.speed = d.config.replay_speed;
  options.replay.loop = d.config.loop;
  options.sim = d.config.sim;
  options.allow_remote = d.config.allow_remote;
  if (specs.empty()) {
    specs.push_back("replay:" + bundled_recording_path().string());
    options.replay.loop = !d.config.exit_at_end;
    spdlog::info("no --source given: replaying the bundled recording {}{}", bundled_recording_path().string(),
                 options.replay.loop ? " in a loop (Ctrl-C to stop)" : "");
  }
  for (const std::string& spec : specs) {
    auto source = drivers::open_source(spec, options, error);
    if (!source) return error;
    spdlog::info("source: {}", source->name());
    d.sources.push_back(std::move(source));
    d.source_sinks.push_back(std::make_unique<RoleRateSink>(d.queue));
  }

  // --record-trackers: the header says what the recorded samples went through.
  if (!d.config.record_trackers_file.empty()) {
    std::string offsets;
    for (Role r : kXrRoles) {
      const auto& o = d.config.offsets[static_cast<int>(r)];
      if (!o) continue;
      offsets += fmt::format("{}{} position_m {},{},{} rotation_xyzw {},{},{},{}", offsets.empty() ? "" : "; ", role_name(r),
                             o->position_m.x(), o->position_m.y(), o->position_m.z(), o->rotation.x(), o->rotation.y(),
                             o->rotation.z(), o->rotation.w());
    }
    const std::time_t now = std::time(nullptr);
    char started[32] = {};
    std::strftime(started, sizeof(started), "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
    const TrackerLogMetadata meta{
        {"generator", "bodyd"},
        {"started", started},
        {"sources", d.source_names()},
        {"offsets", offsets.empty() ? "none" : "applied to the samples below: " + offsets},
        {"recentre", "applied to the samples below after a reset (comment lines mark each)"},
        {"calibration", fmt::format("head_height_m {} ({})", d.recon->head_height_m(),
                                    d.calibration.height_calibrated() ? "calibrated" : "the model's size")},
        {"method", std::string(d.recon->name())},
        {"model", d.summary.model_path.empty() ? "none" : d.summary.model_path},
        {"rate_hz", fmt::format("{}", d.config.rate_hz)},
        {"replay", "bodyd --replay FILE --fast, without offsets, with the same method, model, calibration, rate_hz"}};
    if (std::string re = d.recorder.open(d.config.record_trackers_file, meta, d.config.record_trackers_overwrite); !re.empty()) return re;
    spdlog::info("recording every tracker sample to {}", d.config.record_trackers_file);
  }

  // The sockets.
  std::string e = d.open_outputs();
  if (e.empty()) e = d.control.open(d.config);
  if (!e.empty()) {
    d.control.stop();
    d.close_outputs();
    return e;
  }
  spdlog::info("publishing poses on {}{}", d.pub->bound(), d.pub->curve_public_key().empty() ? "" : " (CURVE)");
  for (const auto& slot_ptr : d.outputs) {
    const OutputSlot& slot = *slot_ptr;
    if (slot.primary) continue;
    if (slot.gate.rate_hz() > 0) spdlog::info("output: {} (at most {} poses/s)", slot.output->name(), slot.gate.rate_hz());
    else spdlog::info("output: {}", slot.output->name());
  }
  if (d.control.enabled()) spdlog::info("control socket on {}", d.control.bound());
  if (!d.config.endpoints_file.empty()) {
    // Readable by all, as before: it names endpoints and the public key only.
    const json endpoints{{"pub", d.pub->bound()}, {"control", d.control.bound()}, {"curve_public_key", d.pub->curve_public_key()}};
    if (std::string fe = replace_persisted_file(d.config.endpoints_file, endpoints.dump() + "\n", 0644); !fe.empty()) {
      d.control.stop();
      d.close_outputs();
      return "cannot write the endpoints file: " + fe;
    }
  }
  d.started = true;
  d.recon_thread = std::thread([&d] {
    try {
      d.reconstruction_loop();
    } catch (const std::exception& ex) {
      spdlog::critical("reconstruction thread stopped: {} (a bug: please report it with the log)", ex.what());
      d.fatal.store(true);
      d.notify();
    }
  });
  d.control.start(d);
  return {};
}

int Daemon::run(const volatile std::sig_atomic_t* signal_flag) {
  Impl& d = *impl_;
  if (!d.started) return 1;
  for (;;) {
    if (signal_flag && *signal_flag) {
      spdlog::info("signal received ({}): shutting down", strsignal(static_cast<int>(*signal_flag)));
      break;
    }
    if (d.stop_flag.load() || d.shutdown_requested.load()) break;
    if (d.fatal.load()) break;
    if (d.config.exit_at_end && d.drained.load()) break;
    d.keep_auto_mounting();
    std::unique_lock lock(d.wake_mutex);
    d.wake.wait_for(lock, std::chrono::milliseconds(50));
  }
  stop();
  d.keep_auto_mounting();
  if (d.fatal.load()) return 1;
  if (d.config.exit_at_end && d.drained.load() && !d.head_seen) {
    // Not a success: nothing was published (issue 11). Documented in docs/daemon.md.
    spdlog::error("every source finished without a valid head sample: no pose was published (is the head "
                  "role valid anywhere in the input? docs/tracker-log.md)");
    return 3;
  }
  return 0;
}

void Daemon::request_stop() {
  impl_->stop_flag.store(true);
  impl_->notify();
}

void Daemon::stop() {
  Impl& d = *impl_;
  d.stop_flag.store(true);
  d.notify();
  if (d.recon_thread.joinable()) d.recon_thread.join();
  for (auto& s : d.sources) s->stop();
  d.recorder.close();
  d.control.stop();
  if (d.started)
    spdlog::info("stopped: {} samples in, {} poses out, {} samples dropped ({} of them stale)", d.stats.samples_in.get(),
                 d.stats.frames_out.get(), d.queue.dropped() + d.queue.dropped_stale(), d.queue.dropped_stale());
  d.started = false;
  d.close_outputs();
}

const std::string& Daemon::pub_endpoint() const {
  static const std::string kNone;
  return impl_->pub ? impl_->pub->bound() : kNone;
}
const std::string& Daemon::control_endpoint() const { return impl_->control.bound(); }
const std::string& Daemon::curve_public_key() const {
  static const std::string kNone;
  return impl_->pub ? impl_->pub->curve_public_key() : kNone;
}
json Daemon::status() const { return impl_->status(); }
std::uint64_t Daemon::loop_iterations() const { return impl_->loop_iterations.load(std::memory_order_relaxed); }

}  // namespace bodyd::daemon
