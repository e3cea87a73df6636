// Running under systemd (packaging/systemd/bodyd.service, docs/install.md): readiness,
// watchdog and stop notifications through libsystemd's sd_notify, and logging to the journal.
//
// Outside systemd (no NOTIFY_SOCKET) every call does nothing, so bodyd behaves the same from a
// terminal. The notifications are datagrams on the socket systemd names in NOTIFY_SOCKET; a
// test can stand in for systemd by binding one itself.
#pragma once

#include <chrono>
#include <string>

namespace bodyd::daemon {

class ServiceNotifier {
 public:
  // Reads NOTIFY_SOCKET and WATCHDOG_USEC / WATCHDOG_PID (sd_watchdog_enabled).
  ServiceNotifier();

  // Whether a service manager listens (NOTIFY_SOCKET is set).
  [[nodiscard]] bool active() const { return active_; }
  // The watchdog's ping interval: half of WATCHDOG_USEC (systemd's advice); zero when the
  // service has no watchdog.
  [[nodiscard]] std::chrono::microseconds watchdog_ping_interval() const { return ping_interval_; }

  // READY=1 with a STATUS= line: the sockets are bound and the pipeline runs.
  void ready(const std::string& status) const;
  // WATCHDOG=1: the caller checked that the daemon is alive.
  void watchdog() const;
  // STATUS= only (shown by systemctl status).
  void status(const std::string& status) const;
  // STOPPING=1: shutting down.
  void stopping() const;

 private:
  bool active_ = false;
  std::chrono::microseconds ping_interval_{0};
};

// True when stderr is connected to the journal (JOURNAL_STREAM names stderr's device and
// inode, as systemd sets it for a service's output); bodyd then logs through the journal API
// with priorities instead of timestamped text.
[[nodiscard]] bool stderr_is_journal();

}  // namespace bodyd::daemon
