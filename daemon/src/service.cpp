#include "bodyd/daemon/service.h"

#include <systemd/sd-daemon.h>
#include <sys/stat.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>

namespace bodyd::daemon {

ServiceNotifier::ServiceNotifier() {
  const char* socket = std::getenv("NOTIFY_SOCKET");
  active_ = socket != nullptr && *socket != '\0';
  std::uint64_t usec = 0;
  // > 0 only when WATCHDOG_USEC is set and WATCHDOG_PID (if set) is this process.
  if (active_ && sd_watchdog_enabled(/*unset_environment=*/0, &usec) > 0 && usec > 0)
    ping_interval_ = std::chrono::microseconds(static_cast<std::int64_t>(usec / 2));
}

void ServiceNotifier::ready(const std::string& status) const {
  if (active_) sd_notifyf(0, "READY=1\nSTATUS=%s", status.c_str());
}

void ServiceNotifier::watchdog() const {
  if (active_) sd_notify(0, "WATCHDOG=1");
}

void ServiceNotifier::status(const std::string& status) const {
  if (active_) sd_notifyf(0, "STATUS=%s", status.c_str());
}

void ServiceNotifier::stopping() const {
  if (active_) sd_notify(0, "STOPPING=1");
}

bool stderr_is_journal() {
  // systemd.exec(5): JOURNAL_STREAM is "DEVICE:INODE" of the stream; compare with stderr, since
  // a child process may inherit the variable with its stderr redirected elsewhere.
  const char* stream = std::getenv("JOURNAL_STREAM");
  if (!stream) return false;
  unsigned long long dev = 0, ino = 0;
  if (std::sscanf(stream, "%llu:%llu", &dev, &ino) != 2) return false;
  struct stat st {};
  if (fstat(2, &st) != 0) return false;
  return static_cast<unsigned long long>(st.st_dev) == dev && static_cast<unsigned long long>(st.st_ino) == ino;
}

}  // namespace bodyd::daemon
