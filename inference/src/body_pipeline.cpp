#include "bodyd/inference/body_pipeline.h"

#include <utility>

namespace bodyd {

void BodyPipeline::start_auto_height(const StandingHeightOptions& options) { height_detector_.emplace(options); }

void BodyPipeline::start_still_second(const BodyReference& reference, const Mounting& defaults,
                                      const BodyJointsInPose& body_joints, bool refine_head,
                                      const PoseCalibrationOptions& options) {
  bool body_unmeasured = false;
  for (Role r : kRoles) body_unmeasured |= !is_xr_role(r) && !conditioner_.measured(r);
  refine_head_ = refine_head;
  if (!refine_head && !body_unmeasured) return;
  still_.emplace(reference, defaults, options, body_joints);
  still_defaults_ = defaults;
  still_first_ns_ = INT64_MIN;
}

void BodyPipeline::hold_calibration_pose(PoseCalibrator calibrator, bool apply_height) {
  held_pose_.emplace(std::move(calibrator));
  held_pose_height_ = apply_height;
}

CalibrationPoseEvent BodyPipeline::apply_calibration_pose(const PoseCalibration& c, Reconstructor& reconstructor,
                                                          bool apply_height) {
  for (Role r : kRoles)
    if (c.measured[static_cast<std::size_t>(r)]) conditioner_.set_mounting(r, c.mounting.T_device_joint[static_cast<std::size_t>(r)]);
  reconstructor.reset();  // the inputs jumped
  CalibrationPoseEvent event{c, {}};
  if (!apply_height) return event;
  event.height_error = calibrate_from_head_height(reconstructor, c.head_height_m);
  if (event.height_error.empty()) {
    height_detector_.reset();
    still_.reset();
  }
  return event;
}

StillSecondEvent BodyPipeline::apply_still_second(const PoseCalibration& c, Reconstructor& reconstructor) {
  StillSecondEvent event;
  event.calibration = c;
  if (!c.device_frames) return event;
  // The body trackers it saw (the pose passed the calibration pose's checks: arms hanging, every
  // tracker near its joint and on its side). Without it an uncalibrated body tracker is not used at all.
  bool any_body = false;
  for (Role r : kRoles) {
    const auto i = static_cast<std::size_t>(r);
    if (is_xr_role(r) || !c.measured[i] || conditioner_.measured(r)) continue;
    conditioner_.set_mounting(r, c.mounting.T_device_joint[i]);
    event.body_measured[i] = true;
    any_body = true;
  }
  if (any_body) reconstructor.reset();  // the inputs jumped
  event.mounting_after_body = conditioner_.mounting();
  // The headset's pitch, kept only when plausible; a calibration pose or the mounting file that
  // measured it wins. No fresh history: the head moves by millimetres.
  if (conditioner_.measured(Role::Head) || !refine_head_) return event;
  const RigidTransform& T = c.mounting.T_device_joint[0];
  event.head_change_deg = mounting_difference(T, still_defaults_.T_device_joint[0]).angle_deg;
  if (event.head_change_deg > kMaxStillHeadChangeDeg) {
    event.head = StillSecondEvent::Head::TooFar;
    return event;
  }
  conditioner_.set_mounting(Role::Head, T);
  event.head = StillSecondEvent::Head::Refined;
  return event;
}

RawSampleEvents BodyPipeline::observe_raw(const TrackerSample& raw, std::int64_t arrival_ns, Reconstructor& reconstructor) {
  RawSampleEvents events;
  if (held_pose_)
    if (std::optional<PoseCalibration> c = held_pose_->push(raw)) {
      held_pose_.reset();
      events.calibration_pose = apply_calibration_pose(*c, reconstructor, held_pose_height_);
    }
  if (!still_) return events;
  if (std::optional<PoseCalibration> c = still_->push(raw)) {
    still_.reset();
    events.still_second = apply_still_second(*c, reconstructor);
  } else if (raw.role == Role::Head && raw.valid) {
    if (still_first_ns_ == INT64_MIN) {
      still_first_ns_ = arrival_ns;
    } else if (arrival_ns - still_first_ns_ > kStillSecondWindowNs) {
      still_.reset();
      events.still_second_expired = true;
    }
  }
  return events;
}

std::optional<AutoHeightEvent> BodyPipeline::before_push(const TrackerSample& s, Reconstructor& reconstructor) {
  if (!height_detector_ || s.role != Role::Head) return std::nullopt;
  const std::optional<StandingHeight> h = height_detector_->push(s);
  if (!h) {
    if (!height_detector_->done()) return std::nullopt;
    height_detector_.reset();
    return AutoHeightEvent{AutoHeightEvent::Outcome::NotFound, {}, {}};
  }
  height_detector_.reset();
  if (std::string e = calibrate_from_head_height(reconstructor, h->head_height_m); !e.empty())
    return AutoHeightEvent{AutoHeightEvent::Outcome::Refused, *h, std::move(e)};
  return AutoHeightEvent{AutoHeightEvent::Outcome::Applied, *h, {}};
}

void BodyPipeline::time_restarted() {
  if (height_detector_) height_detector_->reset();
}

SampleEvents BodyPipeline::push(TrackerSample sample, std::int64_t arrival_ns, Reconstructor& reconstructor) {
  SampleEvents events;
  events.raw = observe_raw(sample, arrival_ns, reconstructor);
  if (!conditioner_.uses(sample)) {
    events.used = false;
    return events;
  }
  conditioner_.condition(sample);
  SampleConditioner::finish(sample);
  events.height = before_push(sample, reconstructor);
  reconstructor.push(sample);
  return events;
}

}  // namespace bodyd
