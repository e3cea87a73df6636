// Replay source: feeds recorded tracker samples (a tracker log, docs/tracker-log.md) to the
// pipeline as if a device produced them.
//
// Paced replay releases each sample when (t_ns - t_first) / speed has elapsed on the host
// clock since start and pushes without blocking, like a device; by default it also restamps
// the sample with that host time (CLOCK_MONOTONIC), so a paced replay is indistinguishable
// from a live device and mixes with live sources. Fast replay pushes as soon as the sink has
// room, never loses a sample, and keeps the log's time base (there is no host time to give:
// the same input as an offline run on the log). Looping starts again at the first sample
// with every timestamp shifted by the log's span plus one sample period, so time keeps
// increasing; should the shifted times pass limits::kMaxAbsTimeNs, the time base starts over
// once (time goes backwards; logged, and the daemon starts its reconstruction over).
#pragma once

#include "bodyd/io/source.h"

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace bodyd::drivers {

struct ReplayOptions {
  bool paced = true;    // follow the log's timestamps; false: as fast as the pipeline takes them
  bool loop = false;    // start again at the end (forever, until stop())
  double speed = 1.0;   // paced replay speed factor (2 = twice as fast); must be > 0
  bool restamp = true;  // paced: t_ns = the host time the sample is released; false: keep the log's
  // Paced: a forward jump in the log's time longer than this (seconds of log time) is replayed
  // as a gap of this length, logged and shown in status().last_error, instead of stalling for
  // the whole jump. Shorter gaps (a tracker lost for a while) keep their length.
  double max_gap_s = 5.0;
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
