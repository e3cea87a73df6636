// Pose recordings: write + read round trip, malformed files.
#include "bodyd/protocol/recording.h"
#include "bodyd/protocol/synthetic.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>

namespace bodyd::protocol {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;
using Bytes = std::vector<std::uint8_t>;

Bytes sample_recording(int poses) {
  Bytes file;
  append_recording_header(1'700'000'000'000'000'000, file);
  Bytes frame;
  EXPECT_TRUE(encode_skeleton(synthetic_skeleton(), frame).ok());
  EXPECT_TRUE(append_recording_frame(5, kSkeletonTopic, frame, file).ok());
  for (int i = 0; i < poses; ++i) {
    EXPECT_TRUE(encode_pose(synthetic_pose(static_cast<std::uint64_t>(i)), frame).ok());
    EXPECT_TRUE(append_recording_frame(100 + i, kPoseTopic, frame, file).ok());
  }
  return file;
}

TEST(Recording, HeaderBytes) {
  Bytes b;
  append_recording_header(0x0102030405060708, b);
  const Bytes expected = {'B', 'O', 'D', 'Y', 'D', 'R', 'E', 'C', 1, 0, 0, 0, 24, 0, 0, 0,
                          8, 7, 6, 5, 4, 3, 2, 1};
  EXPECT_EQ(b, expected);
  Bytes r;
  ASSERT_TRUE(append_recording_frame(-1, "ab", Bytes{9, 8, 7}, r).ok());
  const Bytes record = {14, 0, 0, 0, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 2, 'a', 'b', 9, 8, 7};
  EXPECT_EQ(r, record);
}

TEST(Recording, FileRoundTrip) {
  const auto path = std::filesystem::path(::testing::TempDir()) / "bodyd_recording_roundtrip.bdrec";
  const Bytes file = sample_recording(50);
  {
    std::ofstream out(path, std::ios::binary);
    out.write(reinterpret_cast<const char*>(file.data()), static_cast<std::streamsize>(file.size()));
  }
  PoseRecording rec;
  Status s = load_pose_recording(path, rec);
  ASSERT_TRUE(s.ok()) << s.error;
  EXPECT_EQ(rec.created_unix_ns, 1'700'000'000'000'000'000);
  ASSERT_EQ(rec.poses.size(), 50u);
  ASSERT_EQ(rec.skeletons.size(), 1u);
  for (int i = 0; i < 50; ++i) {
    EXPECT_EQ(rec.poses[i].seq, static_cast<std::uint64_t>(i));
    EXPECT_EQ(rec.pose_recv_t_ns[i], 100 + i);
    EXPECT_EQ(rec.poses[i].joints[7].position_m, synthetic_pose(i).joints[7].position_m);
  }
  const SkeletonMessage* sk = find_skeleton(rec, rec.poses[0].skeleton_id);
  ASSERT_NE(sk, nullptr);
  EXPECT_EQ(sk->names, synthetic_skeleton().names);
  EXPECT_EQ(find_skeleton(rec, 12345), nullptr);
  std::filesystem::remove(path);
}

TEST(Recording, UnknownTopicsAreKeptRawAndSkippedWhenDecoding) {
  Bytes file = sample_recording(2);
  ASSERT_TRUE(append_recording_frame(7, "future-topic", Bytes{1, 2, 3}, file).ok());
  Recording raw;
  ASSERT_TRUE(parse_recording(file, raw).ok());
  ASSERT_EQ(raw.frames.size(), 4u);
  EXPECT_EQ(raw.frames[3].topic, "future-topic");
  EXPECT_EQ(raw.frames[3].frame, (Bytes{1, 2, 3}));
}

TEST(Recording, MalformedFiles) {
  Recording rec;
  EXPECT_THAT(parse_recording(Bytes{}, rec).error, HasSubstr("shorter than the 24-byte recording header"));
  Bytes b = sample_recording(3);
  b[1] = 'X';
  EXPECT_THAT(parse_recording(b, rec).error, HasSubstr("wrong magic"));
  b = sample_recording(3);
  b[8] = 2;
  EXPECT_THAT(parse_recording(b, rec).error, HasSubstr("unsupported recording version 2"));
  b = sample_recording(3);
  b[12] = 10;
  EXPECT_THAT(parse_recording(b, rec).error, HasSubstr("header_size"));
  // A record size beyond the limit.
  b = sample_recording(0);
  b.insert(b.end(), {0xff, 0xff, 0xff, 0x7f});
  EXPECT_THAT(parse_recording(b, rec).error, HasSubstr("record 1 at byte"));
  // A topic longer than its record.
  b = sample_recording(0);
  b.insert(b.end(), {9, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 5});
  EXPECT_THAT(parse_recording(b, rec).error, HasSubstr("topic_length 5 does not fit"));
}

TEST(Recording, TruncatedTail) {
  const Bytes full = sample_recording(3);
  Recording rec;
  ASSERT_TRUE(parse_recording(full, rec).ok());
  ASSERT_EQ(rec.frames.size(), 4u);
  // Every cut inside the records is reported, or with allow_truncated_tail dropped.
  for (std::size_t n = kRecordingHeaderSize + 1; n < full.size(); ++n) {
    const Bytes cut(full.begin(), full.begin() + static_cast<std::ptrdiff_t>(n));
    Recording strict;
    const Status s = parse_recording(cut, strict);
    Recording lenient;
    ASSERT_TRUE(parse_recording(cut, lenient, true).ok()) << n;
    if (lenient.truncated_tail) {
      EXPECT_THAT(s.error, HasSubstr("file cut short")) << n;
      EXPECT_LT(lenient.frames.size(), 4u);
    } else {
      EXPECT_TRUE(s.ok()) << n;  // a cut at a record boundary
    }
  }
}

TEST(Recording, FuzzNeverReadsOutOfBounds) {
  std::mt19937 rng(7);
  const Bytes good = sample_recording(4);
  int accepted = 0;
  int rejected = 0;
  for (int iter = 0; iter < 3000; ++iter) {
    Bytes b = good;
    const int flips = 1 + static_cast<int>(rng() % 6);
    for (int k = 0; k < flips; ++k) b[rng() % b.size()] = static_cast<std::uint8_t>(rng());
    if (rng() % 3 == 0) b.resize(rng() % b.size());
    b.shrink_to_fit();
    Recording rec;
    const bool lenient = rng() % 2 == 0;
    const Status s = parse_recording(b, rec, lenient);
    if (!s.ok()) {
      // A rejection says why, and never because the reader overran the buffer.
      ++rejected;
      EXPECT_FALSE(s.error.empty()) << iter;
      EXPECT_THAT(s.error, Not(HasSubstr("internal error"))) << iter;
      continue;
    }
    // What was accepted is exactly what the bytes hold: the header as it stands, then every
    // frame written back record by record gives the input again (all of it, or, with a dropped
    // truncated tail, a proper prefix of it).
    ++accepted;
    EXPECT_TRUE(lenient || !rec.truncated_tail) << iter;
    ASSERT_GE(b.size(), kRecordingHeaderSize) << iter;
    std::uint32_t header_size = 0;
    std::memcpy(&header_size, b.data() + 12, sizeof header_size);
    ASSERT_LE(header_size, b.size()) << iter;
    std::int64_t created = 0;
    std::memcpy(&created, b.data() + 16, sizeof created);
    EXPECT_EQ(rec.created_unix_ns, created) << iter;
    Bytes again(b.begin(), b.begin() + header_size);
    for (const RecordedFrame& f : rec.frames)
      ASSERT_TRUE(append_recording_frame(f.recv_t_ns, f.topic, f.frame, again).ok()) << iter;
    if (rec.truncated_tail) {
      ASSERT_LT(again.size(), b.size()) << iter;
      EXPECT_TRUE(std::equal(again.begin(), again.end(), b.begin())) << iter;
    } else {
      EXPECT_EQ(again, b) << iter;
    }
  }
  // Both outcomes were exercised.
  EXPECT_GT(accepted, 0);
  EXPECT_GT(rejected, 0);
}

TEST(Recording, LoadNamesTheFile) {
  PoseRecording rec;
  EXPECT_THAT(load_pose_recording("/nonexistent/x.bdrec", rec).error, HasSubstr("/nonexistent/x.bdrec: cannot open"));
  const auto path = std::filesystem::path(::testing::TempDir()) / "bodyd_recording_bad.bdrec";
  Bytes file = sample_recording(2);
  file[file.size() - 30] ^= 0xff;  // corrupt the last pose's joint data
  file.back() = 0x7f;
  {
    std::ofstream out(path, std::ios::binary);
    out.write(reinterpret_cast<const char*>(file.data()), static_cast<std::streamsize>(file.size()));
  }
  const Status s = load_pose_recording(path, rec);
  EXPECT_THAT(s.error, HasSubstr(path.string() + ": record 2: pose message"));
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace bodyd::protocol
