// The hand-off of control commands (calibration, model swap) from the control thread to the
// reconstruction thread, which applies them between two poses (the reconstructor is never
// touched by two threads).
#pragma once

#include "bodyd/inference/reconstructor.h"

#include <nlohmann/json.hpp>

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

namespace bodyd::daemon {

struct Command {
  enum class Kind { Height, FromHead, Swap, Recentre, PoseBegin } kind = Kind::Height;
  double height_m = 0.0;                 // Height: the standing head height (0: the model's size)
  double timeout_s = 0.0;                // PoseBegin: how long to wait for the still second, s
  std::uint64_t pose_id = 0;             // PoseBegin: the request's id (its reply's key)
  std::unique_ptr<Reconstructor> recon;  // Swap: the new reconstructor
  std::string model_path;                // Swap: its model file ("" for ik)
};

class CommandChannel {
 public:
  // Control thread: hands `command` over and waits for the reply. If the reconstruction
  // thread has not taken it within `take_timeout`, withdraws it and returns an error reply;
  // once taken, waits for it to finish.
  nlohmann::json run(Command command, std::chrono::milliseconds take_timeout = std::chrono::seconds(5));

  // Reconstruction thread: applies a waiting command, if any, with `apply` (which returns
  // the reply). Cheap when nothing waits (one atomic load).
  void serve(const std::function<nlohmann::json(Command&)>& apply);

 private:
  std::mutex mutex_;
  std::condition_variable done_cv_;
  std::optional<Command> pending_;
  std::atomic<bool> waiting_{false};
  bool done_ = false;
  nlohmann::json result_;
};

}  // namespace bodyd::daemon
