// The VMC protocol, marionette side (`bodyd --output vmc:HOST:PORT`, docs/vmc.md):
// one OSC bundle per pose, with the pose retargeted to Unity's humanoid (motion/humanoid.h).
//
// Bundle contents, in this order (protocol.vmc.info, "Marionette spec"):
//   /VMC/Ext/OK        i 1                         (a model is loaded: the bones below are valid)
//   /VMC/Ext/T         f seconds                   (the pose's time since the output's first pose)
//   /VMC/Ext/Root/Pos  s "root" f px py pz qx qy qz qw   (the avatar root: origin, identity)
//   /VMC/Ext/Bone/Pos  s NAME   f px py pz qx qy qz qw   (per bone of kHumanoidBones, in order:
//                       Transform.localPosition and .localRotation, Unity axes, metres)
// The bundle's time tag is "immediately" (1): receivers apply it on arrival.
#pragma once

#include "bodyd/base/non_copyable.h"
#include "bodyd/io/output.h"
#include "bodyd/motion/humanoid.h"

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace bodyd::daemon {
namespace vmc {

inline constexpr std::string_view kDefaultHost = "127.0.0.1";
inline constexpr int kDefaultPort = 39539;  // VMC receivers' (marionettes') usual port
inline constexpr std::size_t kMessagesPerBundle = 3 + kHumanoidBones.size();

// Encodes the bundle of one pose (pure: no I/O). The bundle's messages are built once, at
// construction (liblo, io/osc/osc_sender.h); encode() rewrites their numbers in place, so
// it does not allocate.
class BundleEncoder : NonCopyable {
 public:
  BundleEncoder();
  ~BundleEncoder();

  // The serialised bundle; valid until the next call. Empty if liblo failed (out of memory).
  [[nodiscard]] const std::vector<std::uint8_t>& encode(const UnityPose& pose, float time_s);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vmc

// The output's factory (registered in io/outputs.cpp as "vmc"). Target HOST:PORT,
// default kDefaultHost:kDefaultPort; options: only the daemon's `rate`.
[[nodiscard]] std::unique_ptr<Output> make_vmc_output(const OutputSpec& spec, const OutputEnv& env, std::string& error);

}  // namespace bodyd::daemon
