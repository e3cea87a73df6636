// The VMC bundle encoding (bodyd/io/vmc/vmc.h), on the shared OscBundle (osc_sender.h).
#include "bodyd/io/vmc/vmc.h"

#include "osc/osc_sender.h"

#include <lo/lo.h>

namespace bodyd::daemon::vmc {

struct BundleEncoder::Impl {
  OscBundle bundle;
  int time_index = -1, root_index = -1;
  std::array<int, kHumanoidBones.size()> bone_index{};

  // A message "s f f f f f f f": a name, then position x y z and rotation x y z w (all 0 here).
  int add_transform(const char* path, std::string_view name) {
    lo_message m = lo_message_new();
    lo_message_add_string(m, std::string(name).c_str());
    for (int k = 0; k < 7; ++k) lo_message_add_float(m, 0.0f);
    return bundle.add_message(path, m);
  }

  void set_transform(int index, const Vec3& p, const Quat& q) {
    const double v[7] = {p.x(), p.y(), p.z(), q.x(), q.y(), q.z(), q.w()};
    for (int k = 0; k < 7; ++k) bundle.set_float(index, 1 + k, static_cast<float>(v[k]));  // arg 0 is the name
  }
};

BundleEncoder::BundleEncoder() : impl_(std::make_unique<Impl>()) {
  lo_message ok = lo_message_new();
  lo_message_add_int32(ok, 1);
  impl_->bundle.add_message("/VMC/Ext/OK", ok);
  impl_->time_index = impl_->bundle.add_floats("/VMC/Ext/T", 1);
  impl_->root_index = impl_->add_transform("/VMC/Ext/Root/Pos", "root");
  impl_->set_transform(impl_->root_index, Vec3::Zero(), Quat::Identity());
  for (std::size_t b = 0; b < kHumanoidBones.size(); ++b)
    impl_->bone_index[b] = impl_->add_transform("/VMC/Ext/Bone/Pos", kHumanoidBones[b].unity);
}

BundleEncoder::~BundleEncoder() = default;

const std::vector<std::uint8_t>& BundleEncoder::encode(const UnityPose& pose, float time_s) {
  impl_->bundle.set_float(impl_->time_index, 0, time_s);
  for (std::size_t b = 0; b < kHumanoidBones.size(); ++b)
    impl_->set_transform(impl_->bone_index[b], pose.local_positions[b], pose.local_rotations[b]);
  return impl_->bundle.serialise();
}

}  // namespace bodyd::daemon::vmc
