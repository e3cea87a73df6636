// Unit tests of the output interface (spec parsing, options, rate gate, the registry, the
// config file's "outputs") and of the VRChat output's conversions (docs/outputs.md).
//
// Golden values of the conversions are derived by hand from the definitions (Unity's
// Quaternion.Euler(x, y, z) = Ry(y) Rx(x) Rz(z), the mirror S = diag(1, 1, -1)); the other
// direction is built with Eigen's AngleAxis, independently of the code under test.
#include "bodyd/daemon/config.h"
#include "bodyd/io/output.h"
#include "bodyd/io/vrchat/vrchat.h"
#include "bodyd/motion/limits.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <limits>
#include <random>

namespace bodyd {
namespace {

using daemon::OutputSpec;
namespace vrchat = daemon::vrchat;

constexpr double kDeg = M_PI / 180.0;

// Unity's Quaternion.Euler(x, y, z), degrees, built from its definition with Eigen.
Quat unity_euler(double x, double y, double z) {
  return Quat(Eigen::AngleAxisd(y * kDeg, Vec3::UnitY()) * Eigen::AngleAxisd(x * kDeg, Vec3::UnitX()) *
              Eigen::AngleAxisd(z * kDeg, Vec3::UnitZ()));
}

double angle_between_deg(const Quat& a, const Quat& b) { return a.angularDistance(b) / kDeg; }

void expect_vec(const Vec3& got, const Vec3& want, double tol, const char* what) {
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(got[k], want[k], tol) << what << " component " << k << ": got " << got.transpose();
}

// ------------------------------------------------------------------------ specs

TEST(OutputSpec, ParsesSchemeTargetAndOptions) {
  OutputSpec spec;
  std::string error;
  ASSERT_TRUE(daemon::parse_output_spec("vrchat:127.0.0.1:9000?slots=hip,feet,knees&rate=60", spec, error)) << error;
  EXPECT_EQ(spec.scheme, "vrchat");
  EXPECT_EQ(spec.target, "127.0.0.1:9000");
  EXPECT_EQ(spec.options.at("slots"), "hip,feet,knees");
  EXPECT_EQ(spec.options.at("rate"), "60");
  double rate = 0;
  ASSERT_TRUE(daemon::take_rate_option(spec, rate, error)) << error;
  EXPECT_DOUBLE_EQ(rate, 60.0);
  EXPECT_EQ(spec.options.count("rate"), 0u);

  ASSERT_TRUE(daemon::parse_output_spec("vrchat", spec, error));
  EXPECT_EQ(spec.scheme, "vrchat");
  EXPECT_TRUE(spec.target.empty());
  ASSERT_TRUE(daemon::parse_output_spec("vrchat?slots=hip", spec, error));
  EXPECT_TRUE(spec.target.empty());
  EXPECT_EQ(spec.options.at("slots"), "hip");
  ASSERT_TRUE(daemon::parse_output_spec("zmq:tcp://127.0.0.1:5000", spec, error));
  EXPECT_EQ(spec.target, "tcp://127.0.0.1:5000");
}

TEST(OutputSpec, MalformedSpecsAreErrors) {
  OutputSpec spec;
  std::string error;
  EXPECT_FALSE(daemon::parse_output_spec("", spec, error));
  EXPECT_FALSE(daemon::parse_output_spec(":9000", spec, error));
  EXPECT_FALSE(daemon::parse_output_spec("vrchat:?slots", spec, error));
  EXPECT_NE(error.find("KEY=VALUE"), std::string::npos) << error;
  EXPECT_FALSE(daemon::parse_output_spec("vrchat:?rate=1&rate=2", spec, error));
  EXPECT_NE(error.find("twice"), std::string::npos) << error;
  // Issue 43 item 12: a rate is 0 (every pose) or within limits::kMinPoseRateHz .. kMaxRateHz.
  for (const char* bad : {"vrchat?rate=fast", "vrchat?rate=-1", "vrchat?rate=nan", "vrchat?rate=60Hz", "vrchat?rate=1e-12",
                          "vrchat?rate=0.09", "vrchat?rate=10001"}) {
    ASSERT_TRUE(daemon::parse_output_spec(bad, spec, error)) << bad;
    double rate = 0;
    EXPECT_FALSE(daemon::take_rate_option(spec, rate, error)) << bad;
    EXPECT_NE(error.find("rate"), std::string::npos) << error;
  }
}

TEST(OutputRegistry, UnknownSchemesOptionsAndTargetsAreClearErrors) {
  daemon::DaemonConfig config;
  const daemon::OutputEnv env{config};
  auto make = [&](const std::string& text, std::string& error) {
    OutputSpec spec;
    double rate = 0;
    if (!daemon::parse_output_spec(text, spec, error) || !daemon::take_rate_option(spec, rate, error)) return false;
    return daemon::make_output(spec, env, error) != nullptr;
  };
  std::string error;
  EXPECT_FALSE(make("osc:127.0.0.1:9000", error));
  EXPECT_NE(error.find("unknown output \"osc\""), std::string::npos) << error;
  EXPECT_NE(error.find("vrchat"), std::string::npos) << error;  // lists the known ones
  EXPECT_FALSE(make("vrchat:127.0.0.1:9000?slot=hip", error));
  EXPECT_NE(error.find("unknown option \"slot\""), std::string::npos) << error;
  EXPECT_FALSE(make("vrchat:127.0.0.1:9000?slots=hip,tail", error));
  EXPECT_NE(error.find("tail"), std::string::npos) << error;
  EXPECT_FALSE(make("vrchat:127.0.0.1:70000", error));
  EXPECT_NE(error.find("70000"), std::string::npos) << error;
  EXPECT_FALSE(make("vrchat:::1:9000", error));
  EXPECT_NE(error.find("brackets"), std::string::npos) << error;
  EXPECT_FALSE(make("zmq:", error));
  EXPECT_TRUE(make("vrchat", error)) << error;
  EXPECT_TRUE(make("vrchat:127.0.0.1:9000?slots=hip,feet,knees,chest,elbows&rate=60", error)) << error;
  EXPECT_TRUE(make("vrchat:[::1]:9000", error)) << error;
}

TEST(OutputRegistry, VrchatOutputNamesTheDefaultLoopbackAddress) {
  daemon::DaemonConfig config;
  OutputSpec spec;
  std::string error;
  ASSERT_TRUE(daemon::parse_output_spec("vrchat", spec, error));
  auto out = daemon::make_output(spec, daemon::OutputEnv{config}, error);
  ASSERT_TRUE(out) << error;
  ASSERT_EQ(out->open(), "");
  EXPECT_EQ(out->name(), "vrchat:127.0.0.1:9000");
  EXPECT_EQ(out->status().value("slots", ""), "hip,left_foot,right_foot");
  out->close();
}

// Issue 20 item 7: an address that is not one receiver's (multicast, unspecified, broadcast)
// is refused like a broadcast address, for both OSC outputs, unless --allow-remote.
TEST(OutputRegistry, MulticastUnspecifiedAndBroadcastNeedAllowRemote) {
  for (const char* text : {"vrchat:224.0.0.1:9000", "vmc:239.1.2.3:39539", "vrchat:0.0.0.0:9000", "vmc:0.0.0.0:39539",
                           "vrchat:255.255.255.255:9000", "vrchat:[ff02::1]:9000", "vmc:[::]:39539"}) {
    SCOPED_TRACE(text);
    daemon::DaemonConfig config;
    OutputSpec spec;
    std::string error;
    ASSERT_TRUE(daemon::parse_output_spec(text, spec, error)) << error;
    auto out = daemon::make_output(spec, daemon::OutputEnv{config}, error);
    ASSERT_TRUE(out) << error;
    const std::string e = out->open();
    EXPECT_NE(e.find("not one receiver's: refused"), std::string::npos) << e;
    EXPECT_NE(e.find("--allow-remote"), std::string::npos) << e;
    // With consent the address is used (the unspecified one is this machine on Linux; the
    // others may have no route here, which is then the error, not the refusal).
    config.allow_remote = true;
    auto allowed = daemon::make_output(spec, daemon::OutputEnv{config}, error);
    ASSERT_TRUE(allowed) << error;
    const std::string e2 = allowed->open();
    EXPECT_EQ(e2.find("not one receiver's"), std::string::npos) << e2;
    if (std::string(text) == "vrchat:0.0.0.0:9000") {
      EXPECT_EQ(e2, "");
    }
    allowed->close();
  }
}

TEST(RateGate, PassesAtMostTheRateAndToleratesJitter) {
  daemon::RateGate every;
  daemon::RateGate gate(30.0);
  int passed = 0;
  for (int i = 0; i < 900; ++i) {  // 10 s at 90 Hz, with +-2 ms of jitter
    const std::int64_t t = static_cast<std::int64_t>(i) * 11'111'111 + ((i % 3) - 1) * 2'000'000;
    EXPECT_TRUE(every.due(t));
    passed += gate.due(t) ? 1 : 0;
  }
  EXPECT_NEAR(passed, 300, 2);
}

// Issue 43 item 12: 1e9 / rate_hz as an int64 is undefined behaviour below about 1.1e-10 Hz, and
// `--rate-hz 1e-12` published every pose. A gate made with an unchecked rate takes the nearest
// rate the config accepts.
TEST(RateGate, ARateOutsideTheLimitsIsTheNearestLimit) {
  daemon::RateGate tiny(1e-12);
  EXPECT_EQ(tiny.rate_hz(), limits::kMinPoseRateHz);
  int passed = 0;
  for (int i = 0; i < 900; ++i) passed += tiny.due(static_cast<std::int64_t>(i) * 11'111'111) ? 1 : 0;
  EXPECT_LE(passed, 2);  // 10 s at one pose per 10 s, a quarter period early allowed
  EXPECT_GE(passed, 1);
  EXPECT_EQ(daemon::RateGate(1e300).rate_hz(), limits::kMaxRateHz);
  EXPECT_EQ(daemon::RateGate(std::numeric_limits<double>::infinity()).rate_hz(), limits::kMaxRateHz);
  for (double none : {0.0, -5.0, std::nan("")}) {
    daemon::RateGate every(none);
    EXPECT_EQ(every.rate_hz(), 0.0) << none;
    for (int i = 0; i < 10; ++i) EXPECT_TRUE(every.due(i)) << none;
  }
}

TEST(OutputsConfig, ListOfSpecsAndObjects) {
  daemon::DaemonConfig c;
  const auto j = nlohmann::json::parse(R"({"outputs": [
      "vrchat:127.0.0.1:9000?slots=hip",
      {"type": "vrchat", "target": "192.168.1.20:9000", "slots": ["hip", "feet", "knees"], "rate": 60}]})");
  ASSERT_EQ(daemon::apply_config_json(j, "c.json", c), "");
  ASSERT_EQ(c.outputs.size(), 2u);
  EXPECT_EQ(c.outputs[0], "vrchat:127.0.0.1:9000?slots=hip");
  EXPECT_EQ(c.outputs[1], "vrchat:192.168.1.20:9000?rate=60&slots=hip,feet,knees");
  EXPECT_EQ(daemon::config_to_json(c)["outputs"], nlohmann::json(c.outputs));

  for (const char* bad : {R"({"outputs": "vrchat"})", R"({"outputs": [{"target": "x"}]})",
                          R"({"outputs": [{"type": "vrchat", "slots": [1]}]})",
                          R"({"outputs": [{"type": "vrchat", "slots": "hip&rate=1"}]})"}) {
    daemon::DaemonConfig d;
    const std::string e = daemon::apply_config_json(nlohmann::json::parse(bad), "c.json", d);
    EXPECT_NE(e.find("c.json: outputs"), std::string::npos) << bad << " -> " << e;
  }
}

TEST(OutputsConfig, RepeatableFlag) {
  daemon::DaemonConfig c;
  const char* argv[] = {"bodyd", "--output", "vrchat", "--output", "vrchat:127.0.0.1:9100?slots=elbows"};
  const auto r = daemon::parse_command_line(5, argv, c);
  ASSERT_EQ(r.action, daemon::CliResult::Action::Run);
  EXPECT_EQ(c.outputs, (std::vector<std::string>{"vrchat", "vrchat:127.0.0.1:9100?slots=elbows"}));
}

// ------------------------------------------------------------------------ VRChat slots

TEST(VrchatSlots, NamesGroupsAndErrors) {
  vrchat::SlotMask m = 0;
  std::string error;
  ASSERT_TRUE(vrchat::parse_slots("hip,feet,knees,chest,elbows", m, error)) << error;
  EXPECT_EQ(m, 0xFF);
  ASSERT_TRUE(vrchat::parse_slots("feet", m, error));
  EXPECT_EQ(m, 0b110);  // slots 2 and 3
  ASSERT_TRUE(vrchat::parse_slots("right_elbow,hip", m, error));
  EXPECT_EQ(m, 0b1000'0001);  // slots 8 and 1
  EXPECT_EQ(vrchat::slot_names(m), "hip,right_elbow");
  EXPECT_EQ(vrchat::slot_names(vrchat::kDefaultSlots), "hip,left_foot,right_foot");
  EXPECT_FALSE(vrchat::parse_slots("", m, error));
  EXPECT_FALSE(vrchat::parse_slots("hip,", m, error));
  EXPECT_FALSE(vrchat::parse_slots("head", m, error));
  EXPECT_NE(error.find("\"head\""), std::string::npos) << error;
  // SlimeVR's numbering, which third-party tools rely on.
  const char* joints[] = {"Hips", "Foot_L", "Foot_R", "LowerLeg_L", "LowerLeg_R", "Chest", "LowerArm_L", "LowerArm_R"};
  for (int i = 0; i < 8; ++i) {
    EXPECT_EQ(vrchat::kSlots[static_cast<std::size_t>(i)].number, i + 1);
    EXPECT_EQ(vrchat::kSlots[static_cast<std::size_t>(i)].joint, joints[i]);
  }
}

// ------------------------------------------------------------------------ VRChat conversions

// Hand-derived: each rotation in bodyd space, what a person would see, and Unity's angles.
TEST(VrchatConversion, GoldenRotationsDerivedByHand) {
  struct Case {
    const char* what;
    Quat bodyd;
    Vec3 euler_deg;  // Quaternion.Euler's (x, y, z)
  };
  const double s = std::sqrt(0.5);
  const Case cases[] = {
      {"identity", Quat::Identity(), Vec3(0, 0, 0)},
      // +90 about bodyd +Y turns the user (facing -Z) to face -X: a turn to the left, which
      // in Unity (facing +Z, +y turns right) is y = -90.
      {"turn left", Quat(s, 0, s, 0), Vec3(0, -90, 0)},
      // +90 about bodyd +X tips the user's up (+Y) towards +Z, behind them: a look up, which
      // in Unity (+x pitches the nose down) is x = -90 (gimbal lock: z = 0 by convention).
      {"look up", Quat(s, s, 0, 0), Vec3(-90, 0, 0)},
      // +90 about +Z maps +X to +Y in both spaces (z is the mirrored axis): z = +90.
      {"roll", Quat(s, 0, 0, s), Vec3(0, 0, 90)},
      // Half a turn about X: diag(1, -1, -1) = Ry(180) Rz(180) in Unity's axes.
      {"pi about X", Quat(0, 1, 0, 0), Vec3(0, 180, 180)},
      // Half a turn about Z: diag(-1, -1, 1) = Rz(180).
      {"pi about Z", Quat(0, 0, 0, 1), Vec3(0, 0, 180)},
      // Half a turn about Y: Ry(180), the user turned around.
      {"pi about Y", Quat(0, 0, 1, 0), Vec3(0, 180, 0)},
  };
  for (const Case& c : cases) {
    const vrchat::TrackerPose t = vrchat::tracker_from_bodyd(Vec3(0.1, 0.9, -0.2), c.bodyd);
    expect_vec(t.position_unity, Vec3(0.1, 0.9, 0.2), 1e-12, c.what);
    expect_vec(t.euler_deg_unity, c.euler_deg, 1e-9, c.what);
  }
  // The sign of a zero does not flip 180 to -180 (the output range is (-180, 180]).
  const vrchat::TrackerPose t = vrchat::tracker_from_bodyd(Vec3::Zero(), Quat(0, -0.0, -1, 0.0));
  EXPECT_NEAR(t.euler_deg_unity.y(), 180.0, 1e-9);
}

TEST(VrchatConversion, EulerRoundTripsThroughQuaternionEuler) {
  // Quaternion.Euler(x, y, z) -> our angles -> Quaternion.Euler: the same rotation; and the
  // angles themselves where they are unique (|x| < 90, y and z in (-180, 180)).
  const double xs[] = {-89.0, -45.0, -10.0, 0.0, 10.0, 30.0, 60.0, 89.0};
  const double ys[] = {-179.0, -120.0, -45.0, 0.0, 45.0, 90.0, 179.0};
  const double zs[] = {-170.0, -60.0, 0.0, 60.0, 170.0};
  for (double x : xs)
    for (double y : ys)
      for (double z : zs) {
        const Vec3 e = vrchat::unity_euler_deg_from_quat(unity_euler(x, y, z));
        expect_vec(e, Vec3(x, y, z), 1e-7, "euler");
      }
}

TEST(VrchatConversion, GimbalLockAndNearItKeepTheRotation) {
  for (double x : {90.0, -90.0, 89.9999, -89.9999, 89.99999999})
    for (double y : {-150.0, 0.0, 30.0, 179.0})
      for (double z : {0.0, 20.0, -75.0}) {
        const Quat q = unity_euler(x, y, z);
        const Vec3 e = vrchat::unity_euler_deg_from_quat(q);
        EXPECT_LT(angle_between_deg(unity_euler(e.x(), e.y(), e.z()), q), 1e-5) << x << " " << y << " " << z << " -> "
                                                                                << e.transpose();
        EXPECT_LE(std::abs(e.x()), 90.0 + 1e-9);
      }
  // Exactly at the lock the convention is z = 0, x = +-90.
  const Vec3 e = vrchat::unity_euler_deg_from_quat(unity_euler(90, 30, 20));
  EXPECT_NEAR(e.x(), 90.0, 1e-9);
  EXPECT_NEAR(e.z(), 0.0, 1e-9);
  EXPECT_NEAR(e.y(), 10.0, 1e-7);  // Ry(30) Rx(90) Rz(20) = Ry(30 - 20) Rx(90)
}

TEST(VrchatConversion, RandomRotationsBothWaysWithinFloatPrecision) {
  std::mt19937 rng(7);
  std::normal_distribution<double> n;
  for (int i = 0; i < 2000; ++i) {
    const Quat bodyd = Quat(n(rng), n(rng), n(rng), n(rng)).normalized();
    const Vec3 p(n(rng), n(rng), n(rng));
    const vrchat::TrackerPose t = vrchat::tracker_from_bodyd(p, bodyd);
    EXPECT_GT(t.euler_deg_unity.y(), -180.0);
    EXPECT_LE(t.euler_deg_unity.y(), 180.0);
    EXPECT_GT(t.euler_deg_unity.z(), -180.0);
    EXPECT_LE(t.euler_deg_unity.z(), 180.0);
    // Back to bodyd space by the definitions (not by the code under test): Quaternion.Euler,
    // then the mirror (x, y, z, w) -> (-x, -y, z, w); position (x, y, -z).
    const Quat u = unity_euler(t.euler_deg_unity.x(), t.euler_deg_unity.y(), t.euler_deg_unity.z());
    const Quat back(u.w(), -u.x(), -u.y(), u.z());
    ASSERT_LT(angle_between_deg(back, bodyd), 1e-6) << bodyd.coeffs().transpose();
    expect_vec(Vec3(t.position_unity.x(), t.position_unity.y(), -t.position_unity.z()), p, 0.0, "position");
  }
}

}  // namespace
}  // namespace bodyd
