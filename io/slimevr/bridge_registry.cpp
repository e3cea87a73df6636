// The registry of SlimeVR bridge servers (shared_bridge, slimevr_bridge.h): one server per
// socket path in this process, shared by the steamvr: and monado: sources and the steamvr output.
#include "bodyd/io/slimevr/slimevr_bridge.h"

#include <filesystem>
#include <map>
#include <mutex>

namespace bodyd::drivers::slimevr {

std::shared_ptr<BridgeServer> shared_bridge(const std::string& path) {
  static std::mutex mutex;
  static std::map<std::string, std::weak_ptr<BridgeServer>> servers;
  std::lock_guard lock(mutex);
  std::error_code ec;
  const std::string key = std::filesystem::absolute(path, ec).lexically_normal().string();
  if (auto s = servers[key].lock()) return s;
  auto s = std::make_shared<BridgeServer>(path);
  servers[key] = s;
  return s;
}

}  // namespace bodyd::drivers::slimevr
