// A brief, fixed-seed run of every input fuzz target (input_fuzz_targets.h), part of `make test`:
// each seed of tests/fuzz/<target>/, its prefixes, random mutations of it and random bytes. The
// same targets run for as long as one likes under libFuzzer with `make fuzz`
// (docs/reliability.md). A broken promise aborts the test, like a libFuzzer finding.
#include "input_fuzz_targets.h"
#include "bridge_fuzz_targets.h"

#include "../test_paths.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <vector>

namespace bodyd::test {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;
using Target = void (*)(const std::uint8_t*, std::size_t);

Bytes read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// The seeds of tests/fuzz/<name>/ (sorted, so a run is reproducible), plus `extra` files.
std::vector<Bytes> seeds(const std::string& name, const std::vector<fs::path>& extra = {}) {
  std::vector<fs::path> paths = extra;
  for (const auto& e : fs::directory_iterator(fs::path(BODYD_FUZZ_SEEDS_DIR) / name))
    if (e.is_regular_file()) paths.push_back(e.path());
  std::sort(paths.begin(), paths.end());
  std::vector<Bytes> out;
  for (const auto& p : paths) out.push_back(read_bytes(p));
  return out;
}

// Mutations a byte-level fuzzer makes: overwrite, insert, erase, duplicate a run, splice in a
// "magic" token (numbers at and beyond the limits, separators).
void fuzz_loop(Target target, const std::vector<Bytes>& seed_inputs, int mutations, int random_inputs) {
  ASSERT_FALSE(seed_inputs.empty());
  std::mt19937_64 rng(20261201);  // fixed: a failure reproduces
  static const std::vector<std::string> kTokens = {
      "1e300", "-1e300", "100", "100.0000001", "1e999", "nan", "inf", "-0", "4611686018427387904",
      "9223372036854775807", "-9223372036854775808", ",", "\n", "\r\n", "#", " ", "{", "}", "\"", ":", "[", "]",
      "\x1b[2J", std::string("\0", 1), "\xff\xff\xff\xff", "4294967295", "65535"};
  for (const Bytes& seed : seed_inputs) {
    target(seed.data(), seed.size());
    for (std::size_t n = 0; n < seed.size(); n += 1 + seed.size() / 64) target(seed.data(), n);  // prefixes
  }
  Bytes buf;
  for (int i = 0; i < mutations; ++i) {
    buf = seed_inputs[rng() % seed_inputs.size()];
    const int edits = 1 + static_cast<int>(rng() % 6);
    for (int e = 0; e < edits; ++e) {
      const std::size_t pos = buf.empty() ? 0 : rng() % buf.size();
      switch (rng() % 5) {
        case 0:
          if (!buf.empty()) buf[pos] = static_cast<std::uint8_t>(rng());
          break;
        case 1:
          buf.insert(buf.begin() + static_cast<std::ptrdiff_t>(pos), static_cast<std::uint8_t>(rng()));
          break;
        case 2:
          if (!buf.empty())
            buf.erase(buf.begin() + static_cast<std::ptrdiff_t>(pos),
                      buf.begin() + static_cast<std::ptrdiff_t>(std::min(buf.size(), pos + 1 + rng() % 16)));
          break;
        case 3: {
          const std::string& t = kTokens[rng() % kTokens.size()];
          buf.insert(buf.begin() + static_cast<std::ptrdiff_t>(pos), t.begin(), t.end());
          break;
        }
        default: {
          const std::size_t len = std::min<std::size_t>(buf.size() - pos, 1 + rng() % 64);
          const Bytes run(buf.begin() + static_cast<std::ptrdiff_t>(pos),
                          buf.begin() + static_cast<std::ptrdiff_t>(pos + len));
          buf.insert(buf.begin() + static_cast<std::ptrdiff_t>(rng() % (buf.size() + 1)), run.begin(), run.end());
        }
      }
    }
    target(buf.data(), buf.size());
  }
  for (int i = 0; i < random_inputs; ++i) {
    buf.resize(rng() % 256);
    for (auto& b : buf) b = static_cast<std::uint8_t>(rng());
    target(buf.data(), buf.size());
  }
}

const fs::path kTinyModel = fs::path(BODYD_TEST_DATA_DIR) / "tiny_model.safetensors";

TEST(BriefFuzz, TrackerLog) { fuzz_loop(fuzz_tracker_log, seeds("tracker_log"), 20000, 2000); }
TEST(BriefFuzz, Bvh) { fuzz_loop(fuzz_bvh, seeds("bvh"), 5000, 2000); }
TEST(BriefFuzz, Config) { fuzz_loop(fuzz_config, seeds("config"), 20000, 2000); }
TEST(BriefFuzz, ControlRequest) { fuzz_loop(fuzz_control, seeds("control"), 20000, 2000); }
TEST(BriefFuzz, ModelFile) { fuzz_loop(fuzz_model, seeds("model", {kTinyModel}), 1500, 2000); }
TEST(BriefFuzz, PoseMessage) { fuzz_loop(fuzz_pose_message, seeds("pose_message"), 20000, 2000); }
TEST(BriefFuzz, SlimevrBridge) { fuzz_loop(fuzz_slimevr_bridge, seeds("slimevr_bridge"), 20000, 2000); }
TEST(BriefFuzz, Solarxr) { fuzz_loop(fuzz_solarxr, seeds("solarxr"), 20000, 2000); }

// The bridges' seeds are valid: every frame of a driver stream decodes, the SolarXR bundles ask
// for what Monado asks.
TEST(BriefFuzz, BridgeSeedsAreValidInputs) {
  namespace sv = drivers::slimevr;
  for (const Bytes& s : seeds("slimevr_bridge")) {
    std::size_t at = 0, frames = 0;
    while (at < s.size()) {
      const sv::FrameView f = sv::next_frame(s.data() + at, s.size() - at);
      ASSERT_EQ(f.result, sv::FrameResult::Frame);
      sv::Message m;
      std::string e;
      EXPECT_TRUE(sv::decode_message(f.payload, f.payload_bytes, m, e)) << e;
      at += f.frame_bytes;
      ++frames;
    }
    EXPECT_GT(frames, 1u);
  }
  int polls = 0, starts = 0, settings = 0;
  for (const Bytes& s : seeds("solarxr")) {
    daemon::solarxr::Request r;
    std::string e;
    ASSERT_TRUE(daemon::solarxr::decode_request(s.data(), s.size(), r, e)) << e;
    polls += r.polls;
    starts += r.start_feed;
    settings += static_cast<int>(r.settings_requests.size());
  }
  EXPECT_EQ(polls, 1);
  EXPECT_EQ(starts, 1);
  EXPECT_EQ(settings, 1);
}

// The seeds reach past the first check: each is a valid input of its reader (a seed that is
// rejected at its first byte would leave the fuzzer to find the format on its own).
TEST(BriefFuzz, SeedsAreValidInputs) {
  for (const Bytes& s : seeds("tracker_log"))
    EXPECT_FALSE(parse_tracker_log(as_text(s.data(), s.size()), "seed").samples.empty());
  for (const Bytes& s : seeds("bvh")) EXPECT_GT(parse_bvh(as_text(s.data(), s.size()), "seed").frame_count(), 0);
  for (const Bytes& s : seeds("config")) {
    daemon::DaemonConfig c;
    EXPECT_EQ(daemon::apply_config_json(nlohmann::json::parse(s.begin(), s.end(), nullptr, true, true), "seed", c),
              "");
  }
  for (const Bytes& s : seeds("control")) {
    FuzzControlTarget target;
    EXPECT_EQ(daemon::handle_control_request(as_text(s.data(), s.size()), target)["ok"], true)
        << std::string(as_text(s.data(), s.size()));
  }
  int poses = 0, skeletons = 0;
  for (const Bytes& s : seeds("pose_message")) {
    protocol::PoseMessage p;
    protocol::SkeletonMessage k;
    poses += protocol::decode_pose(s, p).ok();
    skeletons += protocol::decode_skeleton(s, k).ok();
  }
  EXPECT_GT(poses, 0);
  EXPECT_GT(skeletons, 0);
  const Bytes model = read_bytes(kTinyModel);
  EXPECT_NO_THROW((void)inference::parse_model(std::as_bytes(std::span(model)), "tiny"));
}

}  // namespace
}  // namespace bodyd::test
