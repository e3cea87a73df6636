// The filters' option rows (bodyd/inference/filter_option_keys.h says what they drive).
#include "bodyd/inference/filter_option_keys.h"

#include <algorithm>
#include <array>

namespace bodyd {
namespace {

template <auto Member>
auto& tracker(FilterSettings s) {
  return s.filter.*Member;
}
template <auto Member>
auto& body(FilterSettings s) {
  return s.body_filter.*Member;
}

constexpr std::string_view kTracker = "filter", kBody = "body_filter";

const std::array<FilterOptionKey, 16> kRows{{
    {kTracker, "enabled", &tracker<&OneEuroOptions::enabled>, "!--no-filter", "",
     "no One Euro filter on the tracker samples (config \"filter\": {\"enabled\": false})"},
    {kTracker, "min_cutoff_hz", &tracker<&OneEuroOptions::min_cutoff_hz>, "", "",
     "position cutoff of a still tracker, Hz"},
    {kTracker, "beta_per_m_s", &tracker<&OneEuroOptions::beta_per_m_s>, "", "--filter-beta",
     "cutoff increase per m/s of speed"},
    {kTracker, "d_cutoff_hz", &tracker<&OneEuroOptions::d_cutoff_hz>, "", "", "cutoff of the speed estimate, Hz"},
    {kTracker, "rot_min_cutoff_hz", &tracker<&OneEuroOptions::rot_min_cutoff_hz>, "", "",
     "rotation cutoff of a still tracker, Hz"},
    {kTracker, "rot_beta_per_rad_s", &tracker<&OneEuroOptions::rot_beta_per_rad_s>, "", "--filter-rot-beta",
     "rotation cutoff increase per rad/s of angular speed"},
    {kTracker, "head_correction_cutoff_hz", &tracker<&OneEuroOptions::head_correction_cutoff_hz>, "", "",
     "cutoff of the head correction on a noisy head tracker, Hz"},
    {kTracker, "anchor_cutoff_hz", &tracker<&OneEuroOptions::anchor_cutoff_hz>, "", "",
     "cutoff of the smoothed anchor on a noisy head tracker, Hz (0: off)"},
    {kTracker, "hand_reach_slack_m", &tracker<&OneEuroOptions::hand_reach_slack_m>, "", "",
     "how far a noisy hand may be out of reach before the body chases it, m (0: off)"},
    {kTracker, "arm_soft_zone_m", &tracker<&OneEuroOptions::arm_soft_zone_m>, "", "",
     "soft reach of the arms on a noisy hand tracker, m (0: off)"},
    {kBody, "enabled", &body<&BodyFilterOptions::enabled>, "!--no-body-filter", "",
     "no One Euro filter on the model's decoded body (config \"body_filter\": {\"enabled\": false})"},
    {kBody, "min_cutoff_hz", &body<&BodyFilterOptions::min_cutoff_hz>, "", "", "Hips position cutoff of a still body, Hz"},
    {kBody, "beta_per_m_s", &body<&BodyFilterOptions::beta_per_m_s>, "", "--body-filter-beta",
     "Hips cutoff increase per m/s of speed"},
    {kBody, "d_cutoff_hz", &body<&BodyFilterOptions::d_cutoff_hz>, "", "", "cutoff of the speed estimates, Hz"},
    {kBody, "rot_min_cutoff_hz", &body<&BodyFilterOptions::rot_min_cutoff_hz>, "", "",
     "joint rotation cutoff of a still joint, Hz"},
    {kBody, "rot_beta_per_rad_s", &body<&BodyFilterOptions::rot_beta_per_rad_s>, "", "--body-filter-rot-beta",
     "rotation cutoff increase per rad/s of the joint's angular speed"},
}};

}  // namespace

std::span<const FilterOptionKey> filter_option_keys() { return kRows; }

std::string filter_flag(const FilterOptionKey& row) {
  if (!row.daemon_flag.empty()) return std::string(row.daemon_flag);
  std::string flag = "--" + std::string(row.group) + "-" + std::string(row.name);
  std::replace(flag.begin(), flag.end(), '_', '-');
  return flag;
}

}  // namespace bodyd
