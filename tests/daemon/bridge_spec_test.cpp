// The steamvr/monado specs (docs/outputs.md, docs/drivers.md): defaults, options, and bad specs
// refused with a message naming what is wrong.
#include "bodyd/daemon/config.h"
#include "bodyd/daemon/output.h"
#include "bodyd/drivers/open_source.h"
#include "bodyd/drivers/slimevr_bridge.h"

#include <gtest/gtest.h>

#include <cstdlib>

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

}  // namespace
}  // namespace bodyd
