// The steamvr/monado specs (docs/outputs.md, docs/drivers.md): defaults, options, and bad specs
// refused with a message naming what is wrong.
#include "bodyd/daemon/config.h"
#include "bodyd/io/output.h"
#include "bodyd/io/open_source.h"
#include "bodyd/io/slimevr/slimevr_bridge.h"
#include "bodyd/test/sinks.h"
#include "bodyd/test/temp_dir.h"

#include <gtest/gtest.h>

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <thread>
#include <vector>

namespace bodyd {
namespace {

std::unique_ptr<daemon::Output> make(const std::string& text, std::string& error) {
  static const daemon::DaemonConfig config;
  daemon::OutputSpec spec;
  double rate = 0;
  if (!daemon::parse_output_spec(text, spec, error) || !daemon::take_rate_option(spec, rate, error)) return nullptr;
  return daemon::make_output(spec, daemon::OutputEnv{config}, error);
}

// SteamVR's driver runs in the pressure-vessel container, whose XDG_RUNTIME_DIR is not the
// user's: its socket goes where the driver looks next, $XDG_DATA_HOME/dev.slimevr.SlimeVR
// (or ~/.local/share/...). Monado's sockets stay in the runtime directory.
TEST(BridgeSpecs, DefaultsAreWhereEachDriverLooks) {
  ::setenv("XDG_RUNTIME_DIR", "/run/user/4242", 1);
  ::setenv("XDG_DATA_HOME", "/home/u/.data", 1);
  std::string error;
  auto sv = make("steamvr", error);
  ASSERT_TRUE(sv) << error;
  EXPECT_EQ(sv->name(), "steamvr:/home/u/.data/dev.slimevr.SlimeVR/SlimeVRDriver");
  {
    auto src = drivers::open_source("steamvr", drivers::SourceOptions{}, error);
    ASSERT_TRUE(src) << error;
    EXPECT_EQ(src->name(), "steamvr:/home/u/.data/dev.slimevr.SlimeVR/SlimeVRDriver");
  }
  ::unsetenv("XDG_DATA_HOME");
  auto mo = make("monado?trackers=waist,feet,knees&rate=60", error);
  ASSERT_TRUE(mo) << error;
  EXPECT_EQ(mo->name(), "monado:/run/user/4242/SlimeVRRpc");
  const char* home_was = std::getenv("HOME");
  const std::string saved_home = home_was ? home_was : "";
  ::setenv("HOME", "/home/someone", 1);
  auto home = make("steamvr:~/.local/share/dev.slimevr.SlimeVR/SlimeVRDriver", error);
  ASSERT_TRUE(home) << error;
  EXPECT_EQ(home->name(), "steamvr:/home/someone/.local/share/dev.slimevr.SlimeVR/SlimeVRDriver");
  if (home_was) ::setenv("HOME", saved_home.c_str(), 1);
  ::unsetenv("XDG_RUNTIME_DIR");
  ::setenv("XDG_DATA_HOME", "/data", 1);
  std::string e;
  EXPECT_EQ(drivers::slimevr::socket_path("", drivers::slimevr::kDriverSocketName, e),
            "/data/dev.slimevr.SlimeVR/SlimeVRDriver");
  ::unsetenv("XDG_DATA_HOME");
  ::setenv("HOME", "/home/someone", 1);
  EXPECT_EQ(drivers::slimevr::socket_path("", drivers::slimevr::kDriverSocketName, e,
                                          drivers::slimevr::default_driver_socket_dir),
            "/home/someone/.local/share/dev.slimevr.SlimeVR/SlimeVRDriver");
  if (home_was) ::setenv("HOME", saved_home.c_str(), 1);
}

TEST(BridgeSpecs, BadSpecsSayWhatIsWrong) {
  ::setenv("XDG_RUNTIME_DIR", "/run/user/4242", 1);
  std::string error;
  EXPECT_FALSE(make("steamvr?trackers=waist,tail", error));
  EXPECT_NE(error.find("tail"), std::string::npos) << error;
  EXPECT_NE(error.find("expected waist"), std::string::npos) << error;
  EXPECT_FALSE(make("steamvr?slots=hip", error));
  EXPECT_NE(error.find("slots"), std::string::npos) << error;
  EXPECT_FALSE(make("monado?trackers=", error));
  EXPECT_FALSE(make("steamvr:/" + std::string(200, 'x'), error));
  EXPECT_NE(error.find("too long"), std::string::npos) << error;
}

TEST(BridgeSpecs, SourcesParse) {
  std::string error;
  const auto a = drivers::parse_source_spec("steamvr", error);
  ASSERT_TRUE(a) << error;
  EXPECT_EQ(a->scheme->scheme, "steamvr");
  EXPECT_TRUE(a->argument.empty());
  const auto b = drivers::parse_source_spec("monado:/tmp/x", error);
  ASSERT_TRUE(b) << error;
  EXPECT_EQ(b->scheme->scheme, "monado");
  EXPECT_EQ(b->argument, "/tmp/x");
  EXPECT_FALSE(drivers::parse_source_spec("steamvrx", error));
  EXPECT_NE(error.find("steamvr[:SOCKET]"), std::string::npos) << error;
}

// The framing at its edges (the fuzz target checks the rest): a length that counts itself.
TEST(BridgeSpecs, FramesCountTheirOwnLength) {
  namespace sv = drivers::slimevr;
  const std::uint8_t empty[] = {4, 0, 0, 0};
  EXPECT_EQ(sv::next_frame(empty, 4).result, sv::FrameResult::Frame);
  EXPECT_EQ(sv::next_frame(empty, 4).payload_bytes, 0u);
  const std::uint8_t three[] = {3, 0, 0, 0};
  EXPECT_EQ(sv::next_frame(three, 4).result, sv::FrameResult::TooShort);
  const std::uint8_t big[] = {0x01, 0x04, 0, 0};  // 1025
  EXPECT_EQ(sv::next_frame(big, 4).result, sv::FrameResult::TooLong);
  const std::uint8_t max[] = {0x00, 0x04, 0, 0};  // 1024: wait for the rest
  EXPECT_EQ(sv::next_frame(max, 4).result, sv::FrameResult::NeedMore);
  EXPECT_EQ(sv::next_frame(empty, 3).result, sv::FrameResult::NeedMore);
  std::vector<std::uint8_t> out;
  sv::Encoder enc;
  enc.position(out, 7, Vec3(0.25, 1.5, -0.75), Quat(1, 0, 0, 0));
  const sv::FrameView f = sv::next_frame(out.data(), out.size());
  ASSERT_EQ(f.result, sv::FrameResult::Frame);
  EXPECT_EQ(f.frame_bytes, out.size());
  EXPECT_EQ(out[0] | (out[1] << 8), static_cast<int>(out.size()));
  sv::Message m;
  std::string error;
  ASSERT_TRUE(sv::decode_message(f.payload, f.payload_bytes, m, error)) << error;
  EXPECT_EQ(m.kind, sv::Message::Kind::Position);
  EXPECT_EQ(m.tracker_id, 7);
  EXPECT_TRUE(m.has_position);
  EXPECT_EQ(m.z, -0.75f);
  EXPECT_EQ(m.qw, 1.0f);
}

// Body trackers by their SlimeVR roles (issue 44): the waist (1) feeds the hips as a device pose;
// a Position that is not tracked (data_source IMU, SteamVR's rotation-only fallback, status
// OCCLUDED) gives a body tracker its rotation alone (has_position false) where it makes the
// headset's sample invalid; a status of ERROR makes it lost; shoulders (9) are not used, nor is
// one of bodyd's own virtual trackers fed back.
TEST(BridgeSource, BodyTrackersByRoleAndRotationOnlyWhenNotTracked) {
  namespace sv = drivers::slimevr;
  test::TempDir dir;
  const std::string path = (dir.path / "run" / "SlimeVRDriver").string();
  sv::BridgeServer server(path);
  test::CollectingSink sink;  // what the bridge pushes
  server.attach_sink(&sink, 3);
  server.set_trackers({{1, "bodyd-waist", "bodyd waist", sv::role::kWaist}});  // the steamvr output's
  ASSERT_EQ(server.start(), "");
  EXPECT_EQ(server.source_index(), std::optional<std::uint16_t>(3));

  const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  std::strncpy(addr.sun_path, path.c_str(), sizeof addr.sun_path - 1);
  ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
  sv::Encoder enc;
  // Sends, then waits until the bridge has pushed `samples` in all: each sample is out before
  // the next message arrives, so none is coalesced away on a loaded machine.
  const auto send = [&](const std::vector<std::uint8_t>& bytes, std::size_t samples) {
    ASSERT_EQ(::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL), static_cast<ssize_t>(bytes.size()));
    if (samples > 0) {
      ASSERT_GE(sink.wait_for(samples).size(), samples);
    }
  };
  const Vec3 p(0.1, 0.9, -0.2);
  const Quat q = Quat(Eigen::AngleAxisd(0.7, Vec3(0.3, 1.0, 0.2).normalized()));
  // A Position with data_source IMU: the encoder's (FULL, the last field) with that byte changed.
  const auto position = [&](std::int32_t id, bool imu) {
    std::vector<std::uint8_t> out;
    enc.position(out, id, p, q);
    EXPECT_EQ(out[out.size() - 2], 0x48);  // field 9, varint
    EXPECT_EQ(out.back(), sv::data_source::kFull);
    if (imu) out.back() = static_cast<std::uint8_t>(sv::data_source::kImu);
    return out;
  };
  const auto status = [&](std::int32_t id, std::int32_t st) {
    std::vector<std::uint8_t> out;
    enc.tracker_status(out, id, st);
    return out;
  };
  std::vector<std::uint8_t> added;
  enc.tracker_added(added, 0, "hmd", "hmd", sv::role::kHmd, "test");
  enc.tracker_added(added, 3, "waist", "waist", sv::role::kWaist, "test");
  enc.tracker_added(added, 4, "shoulder", "shoulder", sv::role::kLeftShoulder, "test");
  enc.tracker_added(added, 5, "bodyd-waist", "bodyd waist", sv::role::kWaist, "slimevr");  // bodyd's own, fed back
  send(added, 0);
  send(position(3, false), 1);                  // tracked
  send(position(3, true), 2);                   // IMU: rotation only
  send(status(3, sv::status::kOccluded), 3);    // lost at once
  send(position(3, true), 4);                   // rotation only (SteamVR's rotation-only fallback)
  send(status(3, sv::status::kError), 5);       // lost
  send(position(3, true), 6);                   // still lost
  send(position(4, false), 0);                  // the shoulder: not used
  send(position(0, true), 7);                   // the headset's IMU Position: lost
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  const auto got = sink.wait_for(7);
  const sv::BridgeStats st = server.stats();  // while connected (its devices are listed until it closes)
  ::close(fd);
  ASSERT_EQ(got.size(), 7u);
  for (std::size_t i = 0; i < 6; ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(got[i].sample.role, Role::Hips);
    EXPECT_EQ(got[i].sample.frame, PoseFrame::Device);
    EXPECT_EQ(got[i].source_index, 3);
  }
  EXPECT_TRUE(got[0].sample.valid);
  EXPECT_TRUE(got[0].sample.has_position);
  EXPECT_LT((got[0].sample.position_m - p).norm(), 1e-6);
  for (std::size_t i : {1, 3}) {
    SCOPED_TRACE(i);
    EXPECT_TRUE(got[i].sample.valid);
    EXPECT_FALSE(got[i].sample.has_position);
    EXPECT_LT(got[i].sample.rotation.angularDistance(q), 1e-6);
  }
  EXPECT_FALSE(got[2].sample.valid);
  EXPECT_FALSE(got[4].sample.valid);
  EXPECT_FALSE(got[5].sample.valid);
  EXPECT_EQ(got[6].sample.role, Role::Head);
  EXPECT_FALSE(got[6].sample.valid);
  EXPECT_EQ(st.roles_use.count("waist") ? st.roles_use.at("waist") : "", "hips");
  EXPECT_EQ(st.roles_use.count("shoulder") ? st.roles_use.at("shoulder") : "", "not used");
  EXPECT_EQ(st.roles_use.count("bodyd-waist") ? st.roles_use.at("bodyd-waist") : "", "not used (bodyd's own)");
  EXPECT_GE(st.untrusted, 4u);
  server.attach_sink(nullptr, 0);
  EXPECT_FALSE(server.source_index());
  server.stop();
}

}  // namespace
}  // namespace bodyd
