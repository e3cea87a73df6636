#include "command_channel.h"

#include "bodyd/daemon/control.h"

namespace bodyd::daemon {

nlohmann::json CommandChannel::run(Command command, std::chrono::milliseconds take_timeout) {
  std::unique_lock lock(mutex_);
  pending_ = std::move(command);
  done_ = false;
  waiting_.store(true, std::memory_order_release);
  if (done_cv_.wait_for(lock, take_timeout, [this] { return done_; })) return std::move(result_);
  if (pending_) {
    pending_.reset();
    waiting_.store(false);
    return control_error("the reconstruction thread did not take the command within " +
                         std::to_string(take_timeout.count() / 1000) + " s");
  }
  done_cv_.wait(lock, [this] { return done_; });
  return std::move(result_);
}

void CommandChannel::serve(const std::function<nlohmann::json(Command&)>& apply) {
  if (!waiting_.load(std::memory_order_acquire)) return;
  std::optional<Command> c;
  {
    std::lock_guard lock(mutex_);
    c = std::move(pending_);
    pending_.reset();
    waiting_.store(false);
  }
  if (!c) return;
  nlohmann::json result = apply(*c);
  {
    std::lock_guard lock(mutex_);
    result_ = std::move(result);
    done_ = true;
  }
  done_cv_.notify_all();
}

}  // namespace bodyd::daemon
