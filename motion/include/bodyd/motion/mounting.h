// Device mounting: how each tracked device sits on the body (docs/conventions.md "Device frames").
//
// A device pose (TrackerSample::frame == PoseFrame::Device) is the pose of the device in the
// common XR convention: right-handed, +Y up, the headset at the point between the eyes looking
// along its -Z, a controller at its OpenXR grip pose (origin at the palm's centroid, -Z through
// the tube the curled fingers make from little finger to thumb, +X normal to the palm: away from
// the palm for the left hand, into it for the right). The reconstruction wants the skeleton's
// joint (Head, Hand_L, Hand_R), so each role has a mounting T_device_joint, the joint's pose in
// the device's frame:  T_world_joint = T_world_device * T_device_joint.
//
// The default mounting is derived, not typed in: a BodyReference measured on the training split
// (how the Head joint sits when the head is upright and looks ahead; how the wrists sit when the
// arms hang relaxed; bodyd-bvh reference), the rule that in that pose the headset looks straight
// ahead and each controller points straight ahead (a hanging fist's finger tube is horizontal),
// and two documented typical offsets (kEyeAboveHeadJointM / kEyeAheadOfHeadJointM,
// kGripToWrist*). A calibration pose (inference/calibration.h) measures the same from the user.
#pragma once

#include "bodyd/base/user_error.h"
#include "bodyd/motion/bvh.h"
#include "bodyd/motion/tracker.h"

#include <array>
#include <filesystem>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>

namespace bodyd {

// A rigid transform T_a_b: maps b coordinates to a coordinates (p_a = rotation * p_b + position_m).
struct RigidTransform {
  Vec3 position_m = Vec3::Zero();
  Quat rotation = Quat::Identity();
};
[[nodiscard]] RigidTransform compose(const RigidTransform& T_a_b, const RigidTransform& T_b_c);  // T_a_c
[[nodiscard]] RigidTransform inverse(const RigidTransform& T_a_b);                               // T_b_a
// The sample's pose as a transform (T_world_device or T_world_joint).
[[nodiscard]] RigidTransform pose_of(const TrackerSample& s);

// Typical geometry (docs/conventions.md "Device frames"): the eyes are about 10 cm above and 8 cm
// in front of the Head joint (the base of the skull) of an upright head; the wrist joint, seen
// from the OpenXR grip pose of a hand hanging relaxed with the controller pointing ahead, is
// 6 cm above the grip point (the palm's centroid is about 6 cm from the wrist along the hand)
// and 2 cm towards the back of the hand (the grip point is on the palm's surface).
inline constexpr double kEyeAboveHeadJointM = 0.10;
inline constexpr double kEyeAheadOfHeadJointM = 0.08;
inline constexpr double kGripToWristAlongHandM = 0.06;
inline constexpr double kGripToWristAcrossPalmM = 0.02;

// The per-role mounting, indexed by Role.
struct Mounting {
  std::array<RigidTransform, kRoleCount> T_device_joint{};
};

// A device sample mapped to its joint: T_world_joint = T_world_device * T_device_joint (frame
// becomes Joint). A joint sample or an invalid one is returned unchanged.
[[nodiscard]] TrackerSample device_to_joint(const TrackerSample& s, const RigidTransform& T_device_joint);
// The inverse (what a device mounted with T_device_joint reports for a joint sample): frame
// becomes Device. A device sample or an invalid one is returned unchanged.
[[nodiscard]] TrackerSample joint_to_device(const TrackerSample& s, const RigidTransform& T_device_joint);

// The body-facing frame used below: +Z forward, +Y up, +X the body's left (bodyd's forward,
// docs/vr-apps.md). A device looking (pointing) straight ahead has its XR axes turned 180 degrees
// about +Y from it: kXrFromFacing maps facing coordinates to such a device's coordinates.
[[nodiscard]] const Quat& xr_from_facing();

// What the training data says about a standing body, in the facing frame (bodyd-bvh reference;
// docs/conventions.md "Device frames"). Stored in data/body-reference.json.
struct BodyReference {
  // The Head joint's rotation in the facing frame when upright and looking ahead (the mean over
  // relaxed still standing frames), and the spread of its pitch and roll over those frames.
  Quat head_in_facing = Quat::Identity();
  double head_pitch_sd_deg = 0.0, head_roll_sd_deg = 0.0;
  // Each wrist joint's rotation in the facing frame when the arms hang relaxed (left, right),
  // and the spread (RMS geodesic angle to the mean).
  std::array<Quat, 2> hand_in_facing{Quat::Identity(), Quat::Identity()};
  std::array<double, 2> hand_sd_deg{0.0, 0.0};
  // Where the Head joint is relative to the wrists' midpoint in that pose, in the facing frame
  // (x: left, y: up, z: ahead; metres, and as a ratio of heights), with spreads.
  double head_ahead_of_wrists_m = 0.0, head_ahead_sd_m = 0.0;
  double head_over_wrist_height = 0.0, head_over_wrist_height_sd = 0.0;
  // Provenance.
  int clips = 0;
  long frames = 0;
  std::string measured_on;
};

class BodyReferenceError : public UserError {
 public:
  using UserError::UserError;
};

// Measures the reference on clips (the joints named in docs/conventions.md). `measured_on` is
// stored as provenance. Throws BodyReferenceError when no clip has a relaxed still standing frame.
[[nodiscard]] BodyReference measure_body_reference(std::span<const Motion> clips, std::string measured_on);
// JSON text ("format": "bodyd-body-reference v1") and back. parse throws BodyReferenceError
// naming `source` and the field.
[[nodiscard]] std::string body_reference_json(const BodyReference& reference);
[[nodiscard]] BodyReference parse_body_reference(std::string_view text, const std::string& source);
[[nodiscard]] BodyReference read_body_reference(const std::filesystem::path& path);
// `path` if not empty, else the bundled data/body-reference.json (paths/data_files.h). Throws
// BodyReferenceError naming where it looked when there is none.
[[nodiscard]] std::filesystem::path find_body_reference(const std::string& path = {});
inline constexpr std::string_view kBodyReferenceFile = "data/body-reference.json";

// The default mounting from a reference (the header comment; docs/conventions.md).
[[nodiscard]] Mounting default_mounting(const BodyReference& reference);

// "head position_m x,y,z rotation_xyzw x,y,z,w; left_hand ...; right_hand ..." (logs, headers),
// then each body tracker's that is not the identity ("; hips ...").
[[nodiscard]] std::string mounting_text(const Mounting& mounting);
[[nodiscard]] std::string transform_text(const RigidTransform& T);

// The mean of unit quaternions that lie close together (sign-aligned to the first, summed,
// normalised); identity for none.
[[nodiscard]] Quat mean_rotation(std::span<const Quat> rotations);

// The joints (Head, Hand_L, Hand_R) of a person standing in the calibration pose exactly as the
// reference describes it: the Head joint at `head_position_m`, the body facing `heading_rad`
// (a turn about +Y from bodyd's +Z), the wrists at the reference's height ratio and depth,
// `half_width_m` to each side. Indexed by Role.
[[nodiscard]] std::array<RigidTransform, kRoleCount> calibration_pose_joints(const BodyReference& reference,
                                                                             const Vec3& head_position_m, double heading_rad,
                                                                             double half_width_m = 0.2);

// The body-facing rotation (facing frame -> world) of a headset pose: a turn about +Y that takes
// +Z to the horizontal part of the headset's line of sight (its -Z).
[[nodiscard]] Quat facing_from_device(const Quat& R_world_device);

// A mounting written out for logs and status: pitch and roll of a headset mounting relative to
// another (degrees), the angle between two rotations.
struct MountingDifference {
  double angle_deg = 0.0;     // geodesic angle between the two rotations
  double position_cm = 0.0;   // distance between the two positions
};
[[nodiscard]] MountingDifference mounting_difference(const RigidTransform& a, const RigidTransform& b);

}  // namespace bodyd
