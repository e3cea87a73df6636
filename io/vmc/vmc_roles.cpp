#include "vmc_roles.h"

#include "bodyd/base/log_rate.h"
#include "bodyd/motion/printable.h"

#include <spdlog/spdlog.h>

#include <iterator>

namespace bodyd::drivers::detail {

namespace {
// Serials in log lines: escaped, and at most this long (a serial is "LHR-1A2B3C4D").
std::string quoted(const std::string& serial) { return "\"" + printable(serial, 64) + "\""; }
int index(Role r) { return static_cast<int>(r); }
}  // namespace

VmcRoles::VmcRoles(std::string name, std::map<std::string, Role> configured)
    : name_(std::move(name)), configured_(std::move(configured)) {
  for (const auto& [serial, role] : configured_) configured_role_[index(role)] = true;
}

std::string VmcRoles::holder(Role role) const {
  for (const auto& [serial, r] : configured_)
    if (r == role) return serial;
  const auto& h = holder_[index(role)];
  return h ? h->serial : std::string();
}

bool VmcRoles::free(Role role) const { return !configured_role_[index(role)] && !holder_[index(role)]; }

std::optional<Role> VmcRoles::role_of(const VmcPose& pose, std::int64_t now_ns) {
  if (auto it = configured_.find(pose.serial); it != configured_.end()) {
    if (it->second == Role::Head) head_ = pose;
    return it->second;
  }
  for (Role r : kRoles) {
    auto& h = holder_[index(r)];
    if (h && h->serial == pose.serial) {
      h->last_ns = now_ns;
      if (r == Role::Head) head_ = pose;
      return r;
    }
  }
  release_stale(now_ns);
  if (pose.device == VmcDevice::Hmd) {
    if (!free(Role::Head)) {
      refuse(pose, Role::Head);
      return std::nullopt;
    }
    const std::string& before = released_[index(Role::Head)];
    assign(pose.serial, Role::Head, now_ns,
           before.empty() ? std::string("the first HMD") : "the next HMD after " + quoted(before) + " went silent");
    head_ = pose;
    // Sides decided relative to another head (a forged first packet, say) are decided again.
    if (!hands_head_.empty() && hands_head_ != pose.serial) {
      for (Role r : {Role::LeftHand, Role::RightHand}) {
        if (!holder_[index(r)]) continue;
        spdlog::info("{}: serial {} is no longer {}: the hands are decided again relative to the new head {}", name_,
                     quoted(holder_[index(r)]->serial), role_name(r), quoted(pose.serial));
        holder_[index(r)].reset();
      }
      hands_head_.clear();
    }
    return Role::Head;
  }
  if (pose.device != VmcDevice::Controller) return std::nullopt;  // trackers: configured only
  const bool left_free = free(Role::LeftHand), right_free = free(Role::RightHand);
  if (!left_free && !right_free) {
    refuse(pose, Role::LeftHand);
    return std::nullopt;
  }
  // Candidates silent for kStaleNs are forgotten, so a burst of made-up serials cannot keep a
  // real controller out for longer than that.
  for (auto it = seen_.begin(); it != seen_.end();)
    it = now_ns - it->second.last_ns >= kStaleNs ? seen_.erase(it) : std::next(it);
  if (!seen_.count(pose.serial) && seen_.size() >= kMaxCandidates) {
    if (log_occurrence(++over_limit_))
      spdlog::warn("{}: controller serial {} ignored: {} controllers without a role are already waiting (the most "
                   "bodyd tracks; {} ignored so far). Name the hands' serials in the spec (left_hand=SERIAL&"
                   "right_hand=SERIAL)",
                   name_, quoted(pose.serial), kMaxCandidates, over_limit_);
    return std::nullopt;
  }
  seen_[pose.serial] = {pose.position_m, now_ns};
  if (!head_) return std::nullopt;  // sides are decided relative to the head
  if (left_free && right_free) {
    if (seen_.size() < 2) return std::nullopt;
    // The first two controllers (std::map orders by serial: deterministic).
    auto a = seen_.begin(), b = std::next(a);
    const Vec3 right_axis = head_->rotation * Vec3::UnitX();
    const double side_a = (a->second.position_m - head_->position_m).dot(right_axis);
    const double side_b = (b->second.position_m - head_->position_m).dot(right_axis);
    const bool a_left = side_a < side_b;
    const std::string left = a_left ? a->first : b->first, right = a_left ? b->first : a->first;
    assign(left, Role::LeftHand, now_ns, "the controller on the head's left");
    assign(right, Role::RightHand, now_ns, "the controller on the head's right");
    hands_head_ = holder(Role::Head);
  } else {
    const Role role = left_free ? Role::LeftHand : Role::RightHand;
    const std::string& before = released_[index(role)];
    assign(pose.serial, role, now_ns,
           before.empty() ? std::string("the only hand not configured") : "the next controller after " + quoted(before) + " went silent");
  }
  for (Role r : kRoles)
    if (holder_[index(r)] && holder_[index(r)]->serial == pose.serial) return r;
  return std::nullopt;
}

void VmcRoles::assign(const std::string& serial, Role role, std::int64_t now_ns, const std::string& why) {
  holder_[index(role)] = Holder{serial, now_ns};
  refused_[index(role)] = 0;  // the next contender's refusals are logged from the first
  seen_.erase(serial);
  spdlog::info("{}: serial {} is {} ({}; set {}={} to fix it)", name_, quoted(serial), role_name(role), why,
               role_name(role), printable(serial, 64));
}

void VmcRoles::release_stale(std::int64_t now_ns) {
  for (Role r : kRoles) {
    auto& h = holder_[index(r)];
    if (!h || now_ns - h->last_ns < kStaleNs) continue;
    spdlog::warn("{}: serial {} sent nothing for {:.1f} s: {} is free for the next {} that sends", name_,
                 quoted(h->serial), static_cast<double>(kStaleNs) * 1e-9, role_name(r),
                 r == Role::Head ? "HMD" : "controller");
    released_[index(r)] = h->serial;
    h.reset();
  }
}

void VmcRoles::refuse(const VmcPose& pose, Role role) {
  // The 1st, 2nd, 4th, 8th... refusal: a second device (or a forged packet) is worth a line,
  // not a line per packet.
  const std::uint64_t n = ++refused_[index(role)];
  if (!log_occurrence(n)) return;
  const bool head = role == Role::Head;
  spdlog::warn("{}: serial {} ignored: {} {} held by {}; a role is never taken from its configured serial or from one "
               "that is streaming ({} ignored so far; name the serials in the spec, e.g. {}=SERIAL, to choose)",
               name_, quoted(pose.serial), head ? "the head" : "both hands", head ? "is" : "are",
               head ? quoted(holder(Role::Head)) : quoted(holder(Role::LeftHand)) + " and " + quoted(holder(Role::RightHand)),
               n, head ? "head" : "left_hand");
}

}  // namespace bodyd::drivers::detail
