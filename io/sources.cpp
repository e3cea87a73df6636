// The registered tracker sources: one row per --source scheme (open_source.h says how to add
// one). Each factory lives in its source's own file.
#include "bodyd/io/open_source.h"

namespace bodyd::drivers {

// The factories and checks (each in its source's file; see open_source.h).
std::unique_ptr<TrackerSource> open_replay_spec(const SourceSpec&, const SourceOptions&, std::string& error);  // replay_source.cpp
std::unique_ptr<TrackerSource> open_sim_spec(const SourceSpec&, const SourceOptions&, std::string& error);     // sim_source.cpp
std::unique_ptr<TrackerSource> open_hid_spec(const SourceSpec&, const SourceOptions&, std::string& error);     // device_list.cpp
std::unique_ptr<TrackerSource> open_usb_spec(const SourceSpec&, const SourceOptions&, std::string& error);     // device_list.cpp
std::string check_device_spec(const SourceSpec&);                                                              // device_list.cpp
std::unique_ptr<TrackerSource> open_network_spec(const SourceSpec&, const SourceOptions&, std::string& error); // network_source.cpp
std::string check_network_spec(const SourceSpec&);                                                             // network_source.cpp
std::unique_ptr<TrackerSource> open_steamvr_spec(const SourceSpec&, const SourceOptions&, std::string& error);  // slimevr/bridge_source.cpp
std::unique_ptr<TrackerSource> open_monado_spec(const SourceSpec&, const SourceOptions&, std::string& error);   // solarxr/monado_source.cpp

const std::vector<SourceScheme>& source_schemes() {
  // scheme, syntax, required argument, bare, declared frame, factory, check
  static const std::vector<SourceScheme> schemes = {
      {"replay", "replay:FILE", "file", false, std::nullopt, open_replay_spec, nullptr},
      {"sim", "sim:FILE.bvh", "file", false, PoseFrame::Joint, open_sim_spec, nullptr},
      {"hid", "hid:VID:PID", "VID:PID", false, PoseFrame::Joint, open_hid_spec, check_device_spec},
      {"usb", "usb:VID:PID", "VID:PID", false, PoseFrame::Joint, open_usb_spec, check_device_spec},
      {"vrchat", "vrchat:[HOST:]PORT", "", false, PoseFrame::Device, open_network_spec, check_network_spec},
      {"vmc", "vmc:[HOST:]PORT", "", false, PoseFrame::Device, open_network_spec, check_network_spec},
      {"udp", "udp:[HOST:]PORT", "", false, PoseFrame::Device, open_network_spec, check_network_spec},
      {"steamvr", "steamvr[:SOCKET]", "", true, PoseFrame::Device, open_steamvr_spec, nullptr},
      {"monado", "monado[:DIR]", "", true, PoseFrame::Device, open_monado_spec, nullptr},
  };
  return schemes;
}

}  // namespace bodyd::drivers
