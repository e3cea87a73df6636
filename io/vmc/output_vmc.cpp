// `--output vmc:HOST:PORT`: the VMC protocol, marionette side (bodyd/io/vmc/vmc.h,
// docs/vmc.md): each pose retargeted to Unity's humanoid (motion/humanoid.h) and
// sent as one OSC bundle.
#include "bodyd/io/vmc/vmc.h"

#include "bodyd/io/output.h"
#include "output_parts.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <memory>
#include <mutex>

namespace bodyd::daemon {
namespace {

class VmcOutput final : public OscOutput {
 public:
  VmcOutput(std::string host, std::string port, const OutputEnv& env)
      : OscOutput("vmc", std::move(host), std::move(port), env) {}

  // The rig is rebuilt for every new skeleton (calibration scales the bones).
  void set_skeleton(const Skeleton& skeleton, const std::vector<std::uint8_t>&) override {
    std::string error;
    rig_ok_ = make_unity_rig(skeleton, rig_, error);
    joint_count_ = skeleton.size();
    if (!rig_ok_)
      spdlog::error("--output {}: the skeleton cannot be retargeted to Unity's humanoid; nothing is sent: {}", name(), error);
    std::lock_guard lock(mutex_);
    rig_error_ = rig_ok_ ? std::string() : error;
  }

  // A VMC receiver draws bodyd's avatar by itself: the user's re-centred space.
  OutputSpace space() const override { return OutputSpace::User; }

  bool send(const OutputFrame& frame, std::string& out_error) override {
    if (!rig_ok_) {
      out_error = "the skeleton is not the humanoid the VMC output knows (see the log)";
      return false;
    }
    const GlobalPose& g = frame.body.global;
    if (static_cast<int>(g.positions.size()) != joint_count_ || static_cast<int>(g.rotations.size()) != joint_count_) {
      out_error = "the pose's joint count differs from its skeleton's";
      return false;
    }
    if (first_t_ns_ == INT64_MIN) first_t_ns_ = frame.t_ns;
    retarget_to_unity(rig_, g, pose_);
    const auto time_s = static_cast<float>(static_cast<double>(frame.t_ns - first_t_ns_) * 1e-9);
    return sender_.send_bundle(encoder_.encode(pose_, time_s), out_error);
  }

  nlohmann::json status() const override {
    nlohmann::json j{{"bundles_sent", sender_.bundles_sent()}};
    std::lock_guard lock(mutex_);
    if (!rig_error_.empty()) j["error"] = rig_error_;
    return j;
  }


 private:
  vmc::BundleEncoder encoder_;
  UnityRig rig_;
  bool rig_ok_ = false;
  int joint_count_ = 0;
  UnityPose pose_;
  std::int64_t first_t_ns_ = INT64_MIN;
  mutable std::mutex mutex_;
  std::string rig_error_;
};

}  // namespace

std::unique_ptr<Output> make_vmc_output(const OutputSpec& spec, const OutputEnv& env, std::string& error) {
  if (std::string e = check_options(spec, {}); !e.empty()) {
    error = e;
    return nullptr;
  }
  std::string host, port;
  if (!osc_target(spec, vmc::kDefaultHost, vmc::kDefaultPort, host, port, error)) return nullptr;
  return std::make_unique<VmcOutput>(host, port, env);
}

}  // namespace bodyd::daemon
