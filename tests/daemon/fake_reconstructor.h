// A small deterministic Reconstructor for daemon tests: the pose is a fixed function of the
// newest valid sample of each role, so tests can recompute it exactly.
#pragma once

#include "bodyd/inference/reconstructor.h"

#include <array>
#include <optional>

namespace bodyd::test {

class FakeReconstructor final : public Reconstructor {
 public:
  FakeReconstructor() {
    model_.names = {"joint_Root", "Hips", "Head", "Hand_L", "Hand_R"};
    model_.parents = {-1, 0, 1, 1, 1};
    model_.offsets = {Vec3::Zero(), Vec3(0, 0.9, 0), Vec3(0, 0.6, 0), Vec3(0.3, 0.4, 0), Vec3(-0.3, 0.4, 0)};
    model_.end_sites.assign(5, std::nullopt);
    set_head_height_m(0.0);
  }
  std::string_view name() const override { return "fake"; }
  const Skeleton& skeleton() const override { return skeleton_; }
  void push(const TrackerSample& s) override {
    if (s.t_ns < last_[static_cast<int>(s.role)]) return;
    last_[static_cast<int>(s.role)] = s.t_ns;
    if (s.valid) latest_[static_cast<int>(s.role)] = s;
    valid_[static_cast<int>(s.role)] = s.valid;
  }
  bool reconstruct(std::int64_t t_ns, BodyPose& out) override {
    if (!latest_[0]) return false;
    ++calls_;
    out.t_ns = t_ns;
    const Vec3 head = latest_[0]->position_m;
    out.global.positions.assign(5, Vec3::Zero());
    out.global.rotations.assign(5, latest_[0]->rotation);
    out.global.rotations[0] = Quat::Identity();
    out.global.positions[1] = head - Vec3(0, 0.6 * scale_, 0);
    out.global.positions[2] = head;
    out.global.positions[3] = latest_[1] ? latest_[1]->position_m : out.global.positions[1];
    out.global.positions[4] = latest_[2] ? latest_[2]->position_m : out.global.positions[1];
    // Something that depends on the time too, so a wrong t_ns shows.
    out.global.positions[0] = Vec3(static_cast<double>(t_ns % 1000000) * 1e-6, 0, 0);
    out.foot_contact = {true, (t_ns / 1000000) % 2 == 0};
    out.tracker_valid = valid_;
    return true;
  }
  void reset() override {
    latest_ = {};
    last_.fill(INT64_MIN);
  }
  void set_head_height_m(double height_m) override {
    height_m_ = height_m > 0 ? height_m : 1.5;
    scale_ = height_m_ / 1.5;
    skeleton_ = model_;
    for (auto& o : skeleton_.offsets) o *= scale_;
  }
  double head_height_m() const override { return height_m_; }
  int calls() const { return calls_; }

 private:
  Skeleton model_, skeleton_;
  double height_m_ = 1.5, scale_ = 1.0;
  std::array<std::optional<TrackerSample>, kRoleCount> latest_{};
  std::array<std::int64_t, kRoleCount> last_{INT64_MIN, INT64_MIN, INT64_MIN};
  std::array<bool, kRoleCount> valid_{};
  int calls_ = 0;
};

// Synthetic tracker samples: all three roles at `rate_hz` for `count` head samples, starting
// at t0_ns, moving along a circle; every 7th left-hand sample invalid.
inline std::vector<TrackerSample> synthetic_samples(int count, double rate_hz = 90.0, std::int64_t t0_ns = 1'000'000'000) {
  std::vector<TrackerSample> out;
  const auto period_ns = static_cast<std::int64_t>(1e9 / rate_hz);
  for (int i = 0; i < count; ++i) {
    const double a = i * 0.05;
    for (Role r : kXrRoles) {
      TrackerSample s;
      s.t_ns = t0_ns + i * period_ns + static_cast<int>(r) * 1000;
      s.role = r;
      s.valid = !(r == Role::LeftHand && i % 7 == 3);
      s.position_m = Vec3(std::cos(a), 1.5 - 0.3 * static_cast<int>(r), std::sin(a));
      s.rotation = quat_from_yaw(a);
      out.push_back(s);
    }
  }
  return out;
}

}  // namespace bodyd::test
