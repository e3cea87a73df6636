// Which VMC serial is which role (docs/vr-apps.md, "VMC in: which serial is which role").
// Internal to the vmc: source (network_source.cpp); its own file so that the rule is tested
// with times chosen by the test (time is a parameter: `now_ns`, monotonic).
//
//   - Serials configured in the spec (?head=SERIAL...) have their role, always; nobody else
//     gets it.
//   - Otherwise the first HMD serial is the head, and the first two controllers are the hands,
//     left being the one further to the head's left (along the headset's -x axis) once both
//     and the head have been seen (the first other controller when one hand is configured).
//   - A role is never taken from a serial that is streaming: while its holder has sent a pose
//     within kStaleNs, another serial's poses are unassigned (a second HMD, a spoofed packet).
//   - A role whose holder has sent nothing for kStaleNs is released: the next serial of that
//     kind to send takes it (both logged).
//   - When the head passes to another serial, hands whose sides were decided relative to the
//     old head are decided again relative to the new one (one forged first packet must not
//     swap the hands for good).
//   - At most kMaxCandidates controllers without a role are remembered; one silent for kStaleNs
//     is forgotten, and a new serial beyond the limit is unassigned (logged at a limited rate).
//
// Serials come from the network: every log line quotes them through printable(). Receiver
// thread only; not thread-safe.
#pragma once

#include "bodyd/io/osc/osc_decode.h"
#include "bodyd/motion/tracker.h"

#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <string>

namespace bodyd::drivers::detail {

class VmcRoles {
 public:
  static constexpr std::int64_t kStaleNs = 1'000'000'000;  // a holder silent this long loses its role
  static constexpr std::size_t kMaxCandidates = 16;        // controllers without a role, remembered at once

  // `name` prefixes log lines ("vmc:39539"); `configured`: serial -> role from the spec.
  VmcRoles(std::string name, std::map<std::string, Role> configured);

  // The role of `pose`'s serial at `now_ns`, or none (the pose is dropped as unassigned).
  [[nodiscard]] std::optional<Role> role_of(const VmcPose& pose, std::int64_t now_ns);

  // The serial holding `role` now (configured or automatic; empty when free). For tests and logs.
  [[nodiscard]] std::string holder(Role role) const;
  [[nodiscard]] std::size_t candidates() const { return seen_.size(); }

 private:
  struct Holder {
    std::string serial;
    std::int64_t last_ns = 0;
  };
  struct Candidate {
    Vec3 position_m = Vec3::Zero();
    std::int64_t last_ns = 0;
  };

  [[nodiscard]] bool free(Role role) const;
  void assign(const std::string& serial, Role role, std::int64_t now_ns, const std::string& why);
  void release_stale(std::int64_t now_ns);
  void refuse(const VmcPose& pose, Role role);

  std::string name_;
  std::map<std::string, Role> configured_;
  std::array<bool, kRoleCount> configured_role_{};
  std::array<std::optional<Holder>, kRoleCount> holder_;  // automatic assignments
  std::map<std::string, Candidate> seen_;                 // controllers without a role yet
  std::optional<VmcPose> head_;                           // the head device's last pose
  std::string hands_head_;                                // the head serial the hands' sides were decided against
  std::array<std::string, kRoleCount> released_;          // who last lost each role (for the log)
  std::array<std::uint64_t, kRoleCount> refused_{};       // per role since its holder got it (rate-limited log)
  std::uint64_t over_limit_ = 0;                          // candidates beyond kMaxCandidates (rate-limited log)
};

}  // namespace bodyd::drivers::detail
