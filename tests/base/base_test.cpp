// The shared helpers of base/ (issue 19 item 4): each against values worked out by hand or
// computed independently, and the edges the old copies disagreed on.
#include "bodyd/base/clock.h"
#include "bodyd/base/little_endian.h"
#include "bodyd/base/log_rate.h"
#include "bodyd/base/loopback.h"
#include "bodyd/base/percentile.h"
#include "bodyd/base/random.h"
#include "bodyd/base/require.h"
#include "bodyd/base/spec_options.h"
#include "bodyd/base/user_error.h"

#include <gtest/gtest.h>

#include <arpa/inet.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <ctime>
#include <limits>
#include <span>
#include <string>
#include <vector>

namespace bodyd {
namespace {

// ---- percentile --------------------------------------------------------------------------------

TEST(Percentile, NearestRankOfKnownData) {
  // 1..10 shuffled: nearest rank k = max(1, ceil(p * 10)).
  const std::vector<int> v = {7, 3, 10, 1, 9, 2, 8, 4, 6, 5};
  EXPECT_EQ(percentile(v, 0.0), 1);    // k = 1: the minimum
  EXPECT_EQ(percentile(v, 0.1), 1);    // ceil(1.0) = 1
  EXPECT_EQ(percentile(v, 0.11), 2);   // ceil(1.1) = 2
  EXPECT_EQ(percentile(v, 0.5), 5);    // ceil(5.0) = 5: the lower median, not interpolated
  EXPECT_EQ(percentile(v, 0.9), 9);
  EXPECT_EQ(percentile(v, 0.99), 10);  // ceil(9.9) = 10
  EXPECT_EQ(percentile(v, 1.0), 10);
  // The evaluation's former test values (there in percent): {5, 1, 4, 2, 3}.
  EXPECT_DOUBLE_EQ(*percentile(std::vector<double>{5, 1, 4, 2, 3}, 0.5), 3.0);
  EXPECT_DOUBLE_EQ(*percentile(std::vector<double>{5, 1, 4, 2, 3}, 0.99), 5.0);
  EXPECT_DOUBLE_EQ(*percentile(std::vector<double>{5, 1, 4, 2, 3}, 0.0), 1.0);
}

TEST(Percentile, P99OfAHundredIsTheNinetyNinthNotTheLast) {
  // round(p (n - 1)), which bodyd-sub used, gave the 100th value here; nearest rank the 99th.
  std::vector<std::int64_t> v(100);
  for (int i = 0; i < 100; ++i) v[static_cast<std::size_t>(i)] = 100 - i;  // 100 .. 1
  EXPECT_EQ(percentile(v, 0.99), 99);
  EXPECT_EQ(percentile(v, 0.5), 50);
  EXPECT_EQ(nearest_rank_index(100, 0.99), 98u);
  EXPECT_EQ(nearest_rank_index(1, 0.99), 0u);
  EXPECT_EQ(nearest_rank_index(3, 0.5), 1u);  // ceil(1.5) = 2
}

TEST(Percentile, SortedAndUnsortedAgree) {
  std::vector<double> v;
  for (int i = 0; i < 37; ++i) v.push_back(static_cast<double>((i * 17) % 37));
  std::vector<double> sorted = v;
  std::sort(sorted.begin(), sorted.end());
  for (double p : {0.0, 0.01, 0.25, 0.5, 0.9, 0.99, 1.0})
    EXPECT_EQ(percentile(v, p), percentile_of_sorted(std::span<const double>(sorted), p)) << p;
}

TEST(Percentile, NoValuesIsNoPercentile) {
  EXPECT_FALSE(percentile(std::vector<double>{}, 0.5).has_value());
  EXPECT_FALSE(percentile_of_sorted(std::span<const double>(), 0.99).has_value());
}

TEST(PercentileDeathTest, AFractionOutsideZeroToOneIsABug) {
  const std::vector<double> v = {1, 2, 3};
  EXPECT_DEATH((void)percentile(v, 99.0), "a percentile is a fraction in \\[0, 1\\]");
  EXPECT_DEATH((void)percentile(v, std::numeric_limits<double>::quiet_NaN()), "bug");
}

// ---- BODYD_REQUIRE ---------------------------------------------------------------------------------

TEST(RequireDeathTest, StopsWithFileLineAndWhat) {
  const std::string detail = "joint 3";
  EXPECT_DEATH(BODYD_REQUIRE(1 + 1 == 3, "arithmetic broke: " + detail),
               "base_test.cpp:[0-9]+: bug: arithmetic broke: joint 3 \\(1 \\+ 1 == 3\\)");
  BODYD_REQUIRE(1 + 1 == 2, "never printed");  // a true condition does nothing
}

// ---- UserError -------------------------------------------------------------------------------------

TEST(UserError, MessageIsWhereWhatTodoWithoutEmptyParts) {
  EXPECT_EQ((Problem{"walk.bvh:12", "expected '{'", "re-export it"}.message()),
            "walk.bvh:12: expected '{'; re-export it");
  EXPECT_EQ((Problem{"", "no input", "give --split FILE"}.message()), "no input; give --split FILE");
  EXPECT_EQ((Problem{"a.log", "read error", ""}.message()), "a.log: read error");
  EXPECT_EQ((Problem{"", "no frames", ""}.message()), "no frames");
}

TEST(UserError, AProblemUnderAnOuterContextKeepsItsWords) {
  const Problem inner{"m.safetensors", "tensor \"w\" is missing", "export it again"};
  const Problem outer = inner.under("method 'diffusion'");
  EXPECT_EQ(outer.where, "method 'diffusion'");
  EXPECT_EQ(outer.todo, "export it again");
  EXPECT_EQ(outer.message(), "method 'diffusion': m.safetensors: tensor \"w\" is missing; export it again");
  EXPECT_EQ((Problem{"", "no frames", ""}.under("clip a").message()), "clip a: no frames");
}

TEST(UserError, WhatIsTheMessageAndTheProblemKeepsItsParts) {
  const UserError e("--rate", "\"fast\" is not a number", "give Hz, e.g. --rate 90");
  EXPECT_STREQ(e.what(), "--rate: \"fast\" is not a number; give Hz, e.g. --rate 90");
  EXPECT_EQ(e.problem().where, "--rate");
  EXPECT_EQ(e.problem().what, "\"fast\" is not a number");
  EXPECT_EQ(e.problem().todo, "give Hz, e.g. --rate 90");
  // A user error is a std::runtime_error, so a program's start that catches std::exception still
  // prints it.
  const std::runtime_error& base = e;
  EXPECT_STREQ(base.what(), e.what());
}

// ---- splitmix64 ------------------------------------------------------------------------------------

TEST(SplitMix64, ReferenceOutputs) {
  // Vigna's splitmix64.c from state 0 and 12345 (computed independently in Python).
  std::uint64_t s = 0;
  EXPECT_EQ(splitmix64(s), 0xe220a8397b1dcdafULL);
  EXPECT_EQ(splitmix64(s), 0x6e789e6aa1b965f4ULL);
  EXPECT_EQ(splitmix64(s), 0x06c45d188009454fULL);
  s = 12345;
  EXPECT_EQ(splitmix64(s), 0x22118258a9d111a0ULL);
  EXPECT_EQ(splitmix64(s), 0x346edce5f713f8edULL);
  // splitmix64_at(seed, i) is output i of the stream, without the state.
  EXPECT_EQ(splitmix64_at(12345, 0), 0x22118258a9d111a0ULL);
  EXPECT_EQ(splitmix64_at(12345, 2), 0x1e9a57bc80e6721dULL);
  EXPECT_EQ(splitmix64_at(0, 0), 0xe220a8397b1dcdafULL);
}

// ---- monotonic_ns ----------------------------------------------------------------------------------

TEST(MonotonicNs, NeverGoesBackAndIsSteadyClock) {
  std::int64_t last = monotonic_ns();
  EXPECT_GT(last, 0);
  for (int i = 0; i < 1000; ++i) {
    const std::int64_t now = monotonic_ns();
    ASSERT_GE(now, last);
    last = now;
  }
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  const std::int64_t kernel_ns = std::int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
  EXPECT_GE(kernel_ns, last);  // the same clock: ours was read first
  EXPECT_GE(monotonic_ns(), kernel_ns);
}

// ---- log_occurrence --------------------------------------------------------------------------------

TEST(LogOccurrence, TheFirstSecondFourthEighthAndSoOn) {
  std::vector<std::uint64_t> logged;
  for (std::uint64_t n = 0; n <= 100; ++n)
    if (log_occurrence(n)) logged.push_back(n);
  EXPECT_EQ(logged, (std::vector<std::uint64_t>{1, 2, 4, 8, 16, 32, 64}));
  EXPECT_TRUE(log_occurrence(std::uint64_t{1} << 63));
  EXPECT_FALSE(log_occurrence(std::numeric_limits<std::uint64_t>::max()));
}

// ---- little-endian ---------------------------------------------------------------------------------

TEST(LittleEndian, KnownBytes) {
  const std::uint8_t b[8] = {0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x88};
  EXPECT_EQ(load_le<std::uint16_t>(b), 0x0201u);
  EXPECT_EQ(load_le<std::uint32_t>(b), 0x04030201u);
  EXPECT_EQ(load_le<std::uint64_t>(b), 0x8807060504030201ULL);
  EXPECT_EQ(load_le<std::int64_t>(b), static_cast<std::int64_t>(0x8807060504030201ULL));
  const std::uint8_t m[2] = {0xFE, 0xFF};
  EXPECT_EQ(load_le<std::int16_t>(m), -2);
  const std::uint8_t one[4] = {0x00, 0x00, 0x80, 0x3F};  // 1.0f
  EXPECT_EQ(load_le<float>(one), 1.0f);
}

TEST(LittleEndian, StoreThenLoadRoundTrips) {
  std::array<std::uint8_t, 8> b{};
  store_le<std::uint32_t>(b.data(), 0xDEADBEEFu);
  EXPECT_EQ(b[0], 0xEF);
  EXPECT_EQ(b[3], 0xDE);
  EXPECT_EQ(load_le<std::uint32_t>(b.data()), 0xDEADBEEFu);
  store_le<std::int16_t>(b.data(), -12345);
  EXPECT_EQ(load_le<std::int16_t>(b.data()), -12345);
  store_le(b.data(), -0.1);
  EXPECT_EQ(load_le<double>(b.data()), -0.1);
  store_le(b.data(), std::int64_t{-1});
  for (std::uint8_t x : b) EXPECT_EQ(x, 0xFF);
}

// ---- spec options ----------------------------------------------------------------------------------

TEST(SpecOptions, SplitsAtTheFirstQuestionMark) {
  EXPECT_EQ(split_spec_query("vrchat:127.0.0.1:9000?slots=hip&rate=60"),
            (std::pair<std::string_view, std::string_view>("vrchat:127.0.0.1:9000", "slots=hip&rate=60")));
  EXPECT_EQ(split_spec_query("vmc:39540"), (std::pair<std::string_view, std::string_view>("vmc:39540", "")));
  EXPECT_EQ(split_spec_query("a?b?c").second, "b?c");
}

TEST(SpecOptions, KeyValuePairsInOrder) {
  std::vector<SpecOption> o;
  EXPECT_EQ(parse_spec_options("slots=hip,feet&rate=60&name=", o), "");
  EXPECT_EQ(o, (std::vector<SpecOption>{{"slots", "hip,feet"}, {"rate", "60"}, {"name", ""}}));
  EXPECT_EQ(parse_spec_options("a=b=c&", o), "");  // the value is all after the first '='; a trailing '&' is fine
  EXPECT_EQ(o, (std::vector<SpecOption>{{"a", "b=c"}}));
  EXPECT_EQ(parse_spec_options("", o), "");
  EXPECT_TRUE(o.empty());
}

TEST(SpecOptions, RefusesWhatIsNotKeyValueAndRepeats) {
  std::vector<SpecOption> o;
  EXPECT_EQ(parse_spec_options("rate", o), "option \"rate\" is not KEY=VALUE");
  EXPECT_EQ(parse_spec_options("=5", o), "option \"=5\" is not KEY=VALUE");
  EXPECT_EQ(parse_spec_options("a=1&&b=2", o), "option \"\" is not KEY=VALUE");
  EXPECT_EQ(parse_spec_options("head=A&head=B", o), "option \"head\" given twice");
}

// ---- loopback --------------------------------------------------------------------------------------

in_addr v4(const char* text) {
  in_addr a{};
  EXPECT_EQ(inet_pton(AF_INET, text, &a), 1) << text;
  return a;
}
in6_addr v6(const char* text) {
  in6_addr a{};
  EXPECT_EQ(inet_pton(AF_INET6, text, &a), 1) << text;
  return a;
}

TEST(Loopback, TheOneRule) {
  EXPECT_TRUE(is_loopback(v4("127.0.0.1")));
  EXPECT_TRUE(is_loopback(v4("127.255.0.9")));
  EXPECT_FALSE(is_loopback(v4("128.0.0.1")));
  EXPECT_FALSE(is_loopback(v4("0.0.0.0")));
  EXPECT_FALSE(is_loopback(v4("192.168.1.20")));
  EXPECT_TRUE(is_loopback(v6("::1")));
  EXPECT_TRUE(is_loopback(v6("::ffff:127.0.0.1")));
  EXPECT_FALSE(is_loopback(v6("::ffff:10.0.0.1")));
  EXPECT_FALSE(is_loopback(v6("::")));
  EXPECT_FALSE(is_loopback(v6("fe80::1")));
  sockaddr_in sin{};
  sin.sin_family = AF_INET;
  sin.sin_addr = v4("127.0.0.2");
  EXPECT_TRUE(is_loopback(reinterpret_cast<const sockaddr&>(sin)));
  sin.sin_addr = v4("10.1.2.3");
  EXPECT_FALSE(is_loopback(reinterpret_cast<const sockaddr&>(sin)));
}

TEST(Loopback, HostsAsWritten) {
  for (const char* h : {"localhost", "127.0.0.1", "127.1.2.3", "::1", "[::1]", "[::ffff:127.0.0.1]"})
    EXPECT_TRUE(is_loopback_host(h)) << h;
  for (const char* h : {"", "0.0.0.0", "*", "lo", "example.com", "localhost.example", "[::]", "192.168.0.1", "[127.0.0.1"})
    EXPECT_FALSE(is_loopback_host(h)) << h;
}

}  // namespace
}  // namespace bodyd
