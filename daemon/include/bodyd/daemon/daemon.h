// The bodyd daemon as a library (the bodyd executable is a thin main around it, and tests
// and the latency benchmark run it in-process).
//
// Threads:
//   source threads  -> SampleQueue (bounded, drop-oldest)  -> reconstruction thread, which
//   reconstructs one pose per new head sample (or at most rate_hz), encodes it (protocol/)
//   and hands it to every output (output.h: the --pub ZeroMQ stream first, then each
//   --output), none of which blocks;
//   control thread: the REP socket (docs/control.md); it hands calibration and model changes
//   to the reconstruction thread, which applies them between two frames.
// The caller's thread runs run(), which only watches for the stop conditions.
#pragma once

#include "bodyd/daemon/config.h"
#include "bodyd/inference/reconstructor.h"

#include <nlohmann/json_fwd.hpp>

#include <csignal>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>

namespace bodyd::daemon {

// Which reconstructor to build.
struct ModelChoice {
  std::string method;                 // "diffusion" or "ik"
  std::filesystem::path model_path;   // the model file (diffusion)
};

// Builds a reconstructor; nullptr and `error` (what is wrong and what to do) on failure.
// Called at start() and, for reload-model, on the control thread.
using ReconstructorFactory =
    std::function<std::unique_ptr<Reconstructor>(const ModelChoice& choice, std::string& error)>;

// The method and model file a configuration asks for. When it asks for the diffusion model
// with no --model and the default model file does not exist, falls back to "ik" and says so
// in `warning`.
[[nodiscard]] ModelChoice choose_model(const DaemonConfig& config, std::string& warning);

// Timing of one published pose (host CLOCK_MONOTONIC, ns), for the latency benchmark and tests.
struct FrameTiming {
  std::uint64_t seq = 0;
  std::int64_t t_ns = 0;              // the pose's time (the head sample's t_ns)
  std::int64_t arrival_ns = 0;        // when the head sample was pushed into the queue
  std::int64_t reconstruct_start_ns = 0;
  std::int64_t reconstruct_end_ns = 0;
  std::int64_t published_ns = 0;      // after the --pub pose stream's zmq_send returned
  std::int64_t outputs_sent_ns = 0;   // after every output (--pub and --output) was sent
  bool sent = false;                  // false: the --pub send failed (counted)
};

class Daemon {
 public:
  Daemon(DaemonConfig config, ReconstructorFactory factory);
  ~Daemon();
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

  // Called on the reconstruction thread after each pose is sent. Must be quick and must not
  // block. Set before start().
  void set_frame_observer(std::function<void(const FrameTiming&)> observer);

  // Builds the reconstructor, opens the sources, binds the sockets and starts the threads.
  // Returns an empty string, or what is wrong and what to do (nothing keeps running then).
  [[nodiscard]] std::string start();

  // Blocks until a stop condition: *signal_flag becomes non-zero (the signal's number, for the
  // log; may be null), a shutdown request, request_stop(), or (exit_at_end) every source
  // finished and everything queued was published. Then stops everything. Returns the process
  // exit code (0, or 1 after a fatal error).
  int run(const volatile std::sig_atomic_t* signal_flag = nullptr);

  // Thread-safe; run() returns soon after.
  void request_stop();
  // Stops and joins every thread, closes the sockets (idempotent; the destructor calls it).
  void stop();

  // The endpoints as bound (a tcp port of * or 0 resolved).
  [[nodiscard]] const std::string& pub_endpoint() const;
  [[nodiscard]] const std::string& control_endpoint() const;
  // The CURVE server public key (Z85), when CURVE is configured; else empty.
  [[nodiscard]] const std::string& curve_public_key() const;

  // The status command's reply (thread-safe).
  [[nodiscard]] nlohmann::json status() const;

  // Turns of the reconstruction loop so far (thread-safe). The loop turns at least every
  // 20 ms while it is alive, samples or not: the systemd watchdog pings while this grows.
  [[nodiscard]] std::uint64_t loop_iterations() const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace bodyd::daemon
