// Replay source: feeds recorded tracker samples (a tracker log, docs/tracker-log.md) to the
// pipeline as if a device produced them.
//
// Samples keep the log's time base in TrackerSample::t_ns (so a replay reconstructs exactly
// what an offline run on the same log computes). Paced replay releases each sample when
// (t_ns - t_first) / speed has elapsed on the host clock since start and pushes without
// blocking, like a device; fast replay pushes as soon as the sink has room and never loses a
// sample. Looping starts again at the first sample with every timestamp shifted by the
// log's span plus one sample period, so time keeps increasing.
#pragma once

#include "bodyd/drivers/source.h"

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace bodyd::drivers {

struct ReplayOptions {
  bool paced = true;    // follow the log's timestamps; false: as fast as the pipeline takes them
  bool loop = false;    // start again at the end (forever, until stop())
  double speed = 1.0;   // paced replay speed factor (2 = twice as fast); must be > 0
};

// A replay of samples already in memory (tests, simulated devices). `name` is reported in
// status(). Samples must be in the order they are to be delivered.
[[nodiscard]] std::unique_ptr<TrackerSource> make_replay_source(std::string name,
                                                                std::vector<TrackerSample> samples,
                                                                const ReplayOptions& options);

// A replay of a tracker log file. Returns nullptr and sets `error` ("file:line: what ...")
// when the file cannot be read or is malformed.
[[nodiscard]] std::unique_ptr<TrackerSource> open_replay_source(const std::filesystem::path& log_path,
                                                                const ReplayOptions& options,
                                                                std::string& error);

}  // namespace bodyd::drivers
