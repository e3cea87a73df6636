// A tracker source over a SlimeVR bridge server (slimevr_bridge.h): what the steamvr: source
// (bridge_source.cpp) and the monado: source (../solarxr/monado_source.cpp) both are.
#pragma once

#include "bodyd/io/slimevr/slimevr_bridge.h"
#include "bodyd/io/open_source.h"
#include "bodyd/io/source.h"

#include <cstdint>
#include <memory>
#include <string>

namespace bodyd::drivers::slimevr {

// SlimeVR's role names (the driver's TrackerRole.hpp), for status and logs (slimevr_bridge.cpp).
[[nodiscard]] std::string role_label(std::int32_t r);

class BridgeSource final : public TrackerSource {
 public:
  BridgeSource(std::string name, std::shared_ptr<BridgeServer> server) : name_(std::move(name)), server_(std::move(server)) {}
  ~BridgeSource() override { stop(); }

  const std::string& name() const override { return name_; }

  std::string start(SampleSink& sink, std::uint16_t source_index) override {
    if (started_) return {};
    server_->attach_sink(&sink, source_index);
    if (std::string e = server_->start(); !e.empty()) {
      server_->attach_sink(nullptr, 0);
      return "--source " + name_ + ": " + e;
    }
    started_ = true;
    return {};
  }

  void stop() override {
    if (!started_) return;
    server_->attach_sink(nullptr, 0);
    server_->stop();
    started_ = false;
  }

  SourceStatus status() const override {
    const BridgeStats b = server_->stats();
    SourceStatus s;
    s.name = name_;
    s.connected = b.clients > 0;
    s.samples = b.samples;
    s.rate_hz = s.connected ? b.rate_hz : 0.0;  // forwarded to the reconstruction (coalesced)
    s.rejected = b.rejected;
    s.rejected_by_reason = b.rejected_by_reason;
    s.last_error = b.last_error;
    s.counters = {{"clients", b.clients},     {"connections", b.connections}, {"disconnects", b.disconnects},
                  {"dropped", b.dropped},     {"frames_in", b.frames_in},     {"ignored", b.ignored},
                  {"refused", b.refused},     {"coalesced", b.coalesced},     {"untrusted", b.untrusted},
                  {"devices_not_listed", b.devices_not_listed}};
    for (const auto& [serial, r] : b.roles_in) {
      const auto use = b.roles_use.find(serial);
      s.devices[serial] = "role " + std::to_string(r) + " (" + role_label(r) + ") -> " +
                          (use == b.roles_use.end() ? std::string("not used") : use->second);
    }
    return s;
  }

 private:
  std::string name_;
  std::shared_ptr<BridgeServer> server_;
  bool started_ = false;
};

// The source `scheme`:`path` on the shared server of `path` (sources steamvr: and monado:); with
// an empty path, nullptr and `error` says the spec and `path_error` (why the path is unknown).
[[nodiscard]] std::unique_ptr<TrackerSource> open_bridge_source(std::string_view scheme, const SourceSpec& spec,
                                                                const std::string& path, const std::string& path_error,
                                                                std::string& error);

}  // namespace bodyd::drivers::slimevr
