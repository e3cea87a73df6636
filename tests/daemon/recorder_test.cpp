// TrackerRecorder (--record-trackers, docs/daemon.md "Recording what came in"; issue 20): the
// recording reaches the file within kFlushIntervalNs of poll() time (a kill -9 loses at most
// that), an existing file, a symbolic link and a FIFO are refused without blocking, --overwrite
// replaces a regular file only.
#include "bodyd/daemon/tracker_recorder.h"
#include "bodyd/motion/tracker_log.h"
#include "../test_paths.h"
#include "zmq_helpers.h"
#include "bodyd/test/files.h"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

namespace bodyd {
namespace {

namespace fs = std::filesystem;
using daemon::TrackerRecorder;
using test::read_file;
using test::samples_on_disk;

TrackerSample head_at(std::int64_t t_ns) {
  TrackerSample s;
  s.t_ns = t_ns;
  s.role = Role::Head;
  s.valid = true;
  s.position_m = Vec3(0, 1.6, 0);
  return s;
}


TEST(TrackerRecorder, PollWritesTheBufferToTheFileWithinTheFlushInterval) {
  test::TempDir dir;
  const fs::path path = dir.path / "rec.csv";
  TrackerRecorder r;
  ASSERT_EQ(r.open(path.string(), {{"generator", "test"}}), "");
  const std::int64_t t0 = 5'000'000'000;
  r.poll(t0);
  for (int i = 0; i < 10; ++i) ASSERT_TRUE(r.record(head_at(1000 + i)));
  r.poll(t0 + TrackerRecorder::kFlushIntervalNs / 2);  // not yet due
  EXPECT_EQ(samples_on_disk(path), 0u);
  r.poll(t0 + TrackerRecorder::kFlushIntervalNs);  // due: on disk without close()
  EXPECT_EQ(samples_on_disk(path), 10u);
  EXPECT_EQ(r.written(), 10u);
  r.close();
  EXPECT_EQ(read_tracker_log(path).samples.size(), 10u);
}

TEST(TrackerRecorder, AnExistingFileIsRefusedUnlessOverwrite) {
  test::TempDir dir;
  const fs::path path = dir.path / "t.csv";
  std::ofstream(path) << "precious\n";
  TrackerRecorder r;
  const std::string e = r.open(path.string(), {});
  EXPECT_NE(e.find("exists"), std::string::npos) << e;
  EXPECT_NE(e.find("--overwrite"), std::string::npos) << e;
  EXPECT_FALSE(r.is_open());
  EXPECT_EQ(read_file(path), "precious\n");
  ASSERT_EQ(r.open(path.string(), {}, /*overwrite=*/true), "");
  ASSERT_TRUE(r.record(head_at(1)));
  r.close();
  EXPECT_EQ(read_tracker_log(path).samples.size(), 1u);
}

TEST(TrackerRecorder, ASymbolicLinkIsNeverFollowed) {
  test::TempDir dir;
  std::ofstream(dir.path / "t") << "precious\n";
  fs::create_symlink(dir.path / "t", dir.path / "l.csv");
  fs::create_symlink(dir.path / "nowhere", dir.path / "dangling.csv");
  for (const bool overwrite : {false, true}) {
    for (const char* name : {"l.csv", "dangling.csv"}) {
      SCOPED_TRACE(std::string(name) + (overwrite ? " --overwrite" : ""));
      TrackerRecorder r;
      const std::string e = r.open((dir.path / name).string(), {}, overwrite);
      EXPECT_NE(e.find("symbolic link"), std::string::npos) << e;
      EXPECT_FALSE(r.is_open());
    }
  }
  EXPECT_EQ(read_file(dir.path / "t"), "precious\n");
  EXPECT_FALSE(fs::exists(dir.path / "nowhere"));
}

TEST(TrackerRecorder, AFifoOrADirectoryIsRefusedWithoutBlocking) {
  test::TempDir dir;
  const fs::path fifo = dir.path / "f.csv";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  fs::create_directory(dir.path / "d.csv");
  for (const bool overwrite : {false, true}) {
    for (const char* name : {"f.csv", "d.csv"}) {
      SCOPED_TRACE(std::string(name) + (overwrite ? " --overwrite" : ""));
      TrackerRecorder r;  // a blocking open of the FIFO would hang here (no reader)
      const std::string e = r.open((dir.path / name).string(), {}, overwrite);
      EXPECT_NE(e.find("not a regular file"), std::string::npos) << e;
      EXPECT_FALSE(r.is_open());
    }
  }
}

}  // namespace
}  // namespace bodyd
