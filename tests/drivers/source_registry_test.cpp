// The source registry (io/sources.cpp) and the UDP protocol table
// (io/osc/network_protocols.cpp) agree with what a user is told: the unknown-kind error
// lists every scheme, each row's spec parses to that row, and the declared device frames are
// the documented ones (docs/drivers.md, "Device frames"). The --source help is checked against
// the same rows in tests/daemon/unit_test.cpp (OpenSource.HelpListsEverySource).
#include "bodyd/io/devices/device_table.h"
#include "bodyd/io/osc/network_source.h"
#include "bodyd/io/open_source.h"

#include "bodyd/io/devices/fake_devices.h"
#include "bodyd/io/devices/hydra.h"
#include "bodyd/io/devices/report.h"

#include "../../io/devices/device_protocol.h"
#include "../../io/osc/network_protocol.h"

#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <tuple>

using namespace bodyd;
using namespace bodyd::drivers;

namespace {

// The list after "expected " in the unknown-kind error, split at ", " and " or ".
std::vector<std::string> listed_in_unknown_kind_error() {
  std::string error;
  EXPECT_FALSE(parse_source_spec("nosuchkind:x", error));
  const std::string marker = "unknown kind; expected ";
  const std::size_t at = error.find(marker);
  EXPECT_NE(at, std::string::npos) << error;
  if (at == std::string::npos) return {};
  std::string list = error.substr(at + marker.size());
  std::vector<std::string> out;
  for (;;) {
    std::size_t cut = list.find(", ");
    std::size_t skip = 2;
    if (cut == std::string::npos) {
      cut = list.find(" or ");
      skip = 4;
    }
    if (cut == std::string::npos) {
      out.push_back(list);
      return out;
    }
    out.push_back(list.substr(0, cut));
    list = list.substr(cut + skip);
  }
}

}  // namespace

TEST(SourceRegistry, TheUnknownKindErrorListsExactlyTheRows) {
  std::vector<std::string> rows;
  for (const SourceScheme& s : source_schemes()) rows.emplace_back(s.syntax);
  EXPECT_EQ(listed_in_unknown_kind_error(), rows);
  EXPECT_GE(rows.size(), 9u);
}

TEST(SourceRegistry, EachRowsSpecParsesToThatRow) {
  std::set<std::string_view> schemes;
  for (const SourceScheme& row : source_schemes()) {
    SCOPED_TRACE(std::string(row.scheme));
    EXPECT_TRUE(schemes.insert(row.scheme).second) << "scheme registered twice";
    ASSERT_NE(row.open, nullptr);
    // The syntax the user reads names the scheme: "scheme:..." or "scheme[:...]".
    const std::string syntax(row.syntax);
    const std::string scheme(row.scheme);
    EXPECT_TRUE(syntax.rfind(scheme + ":", 0) == 0 || syntax.rfind(scheme + "[:", 0) == 0) << syntax;
    EXPECT_EQ(row.bare, syntax.rfind(scheme + "[:", 0) == 0) << "a bare scheme is written scheme[:ARG]";

    std::string error;
    const std::optional<SourceSpec> spec = parse_source_spec(scheme + ":x?frames=device", error);
    ASSERT_TRUE(spec) << error;
    EXPECT_EQ(spec->scheme, &row);
    EXPECT_EQ(spec->argument, "x");
    EXPECT_EQ(spec->text, scheme + ":x");
    EXPECT_EQ(spec->frame, PoseFrame::Device);

    const std::optional<SourceSpec> empty = parse_source_spec(scheme + ":", error);
    if (row.required_argument.empty()) {
      ASSERT_TRUE(empty) << error;
      EXPECT_EQ(empty->scheme, &row);
    } else {
      EXPECT_FALSE(empty);
      EXPECT_EQ(error, "source \"" + scheme + ":\": missing " + std::string(row.required_argument) + " after '" +
                           scheme + ":'");
    }
    const std::optional<SourceSpec> bare = parse_source_spec(scheme, error);
    EXPECT_EQ(bool(bare), row.bare) << error;
    if (bare) {
      EXPECT_EQ(bare->scheme, &row);
    }
  }
}

// What each source delivers when the spec does not say (docs/drivers.md, "Device frames").
TEST(SourceRegistry, DeclaredFramesAreTheDocumentedOnes) {
  const std::map<std::string_view, std::optional<PoseFrame>> documented = {
      {"replay", std::nullopt},         {"sim", PoseFrame::Joint},        {"hid", PoseFrame::Joint},
      {"usb", PoseFrame::Joint},        {"vrchat", PoseFrame::Device},    {"vmc", PoseFrame::Device},
      {"udp", PoseFrame::Device},       {"steamvr", PoseFrame::Device},   {"monado", PoseFrame::Device}};
  for (const SourceScheme& row : source_schemes()) {
    ASSERT_TRUE(documented.count(row.scheme)) << row.scheme << ": add its frame here and to docs/drivers.md";
    EXPECT_EQ(declared_pose_frame(row), documented.at(row.scheme)) << row.scheme;
  }
}

// Every syntax is documented in docs/drivers.md.
TEST(SourceRegistry, DocsDriversNamesEverySyntax) {
  std::ifstream in(std::string(BODYD_SOURCE_DIR) + "/docs/drivers.md");
  ASSERT_TRUE(in) << "docs/drivers.md";
  std::stringstream text;
  text << in.rdbuf();
  for (const SourceScheme& row : source_schemes())
    EXPECT_NE(text.str().find(row.syntax), std::string::npos) << row.syntax << " is not in docs/drivers.md";
}

// Each UDP protocol has a source row of its scheme (and so a --source spec), and the
// protocols' specs parse through their rows.
TEST(SourceRegistry, EveryNetworkProtocolIsASource) {
  ASSERT_FALSE(detail::network_protocols().empty());
  for (const detail::NetworkProtocol& p : detail::network_protocols()) {
    SCOPED_TRACE(std::string(p.scheme));
    std::string error;
    const std::optional<SourceSpec> spec = parse_source_spec(std::string(p.scheme) + ":127.0.0.1:9100", error);
    ASSERT_TRUE(spec) << error;
    EXPECT_EQ(spec->scheme->scheme, p.scheme);
    EXPECT_EQ(check_source_spec(std::string(p.scheme) + ":127.0.0.1:9100"), "");
    ASSERT_NE(p.decoder, nullptr);
    ASSERT_NE(p.option, nullptr);
    const std::optional<NetworkSourceOptions> o =
        parse_network_spec(NetworkKind{p.scheme}, std::string(p.scheme) + ":", "", error);
    EXPECT_EQ(bool(o), p.default_port != 0) << error;
    if (o) {
      EXPECT_EQ(o->port, p.default_port);
    }
    EXPECT_NE(check_source_spec(std::string(p.scheme) + ":1?no_such_option=1").find(p.options_help), std::string::npos);
  }
  std::string error;
  EXPECT_FALSE(parse_network_spec(NetworkKind{"nosuch"}, "nosuch:1", "1", error));
  EXPECT_NE(error.find("no network protocol"), std::string::npos) << error;
  EXPECT_EQ(NetworkKind::Vrchat, NetworkKind{"vrchat"});
  EXPECT_NE(detail::network_protocol(NetworkKind::Vmc), nullptr);
  EXPECT_NE(detail::network_protocol(NetworkKind::Udp), nullptr);
}

// The config check (bodyd exits 2) sees what opening sees: the "frames=" option is not an
// option of the source, bad VID:PID and network options are found.
TEST(SourceRegistry, CheckSourceSpec) {
  EXPECT_EQ(check_source_spec("vrchat:9001?oscquery=off&frames=joint"), "");
  EXPECT_EQ(check_source_spec("hid:1209:B0D1?frames=device"), "");
  EXPECT_NE(check_source_spec("hid:zz:1").find("is not VID:PID"), std::string::npos);
  EXPECT_NE(check_source_spec("vmc:1?tail=X").find("unknown option"), std::string::npos);
  EXPECT_NE(check_source_spec("replay:x?frames=sideways").find("is not joint or device"), std::string::npos);
  EXPECT_EQ(check_source_spec("replay:/no/such/file.csv"), "");  // found when opened
  EXPECT_NE(check_source_spec("bogus:x").find("unknown kind"), std::string::npos);
}

// A spec comes from a config file or a command line a user pasted: an error quotes it escaped,
// so an ESC, CR or LF in it cannot clear the terminal or forge a log line (issue 43 item 1).
TEST(SourceRegistry, ErrorsQuoteTheSpecEscaped) {
  for (const char* spec : {"\x1b[2Jbogus:x\r\nINFO forged", "replay:x?frames=\x1b[2J", "hid:\x1b[31m:1",
                           "vmc:1?tail=\x1b]0;t\x07", "vrchat:\x1b[2J", "udp:\n9"}) {
    const std::string error = check_source_spec(spec);
    SCOPED_TRACE(error);
    EXPECT_FALSE(error.empty());
    for (char c : error) EXPECT_TRUE(c >= 0x20 && c < 0x7f) << "raw byte " << static_cast<int>(c);
  }
  EXPECT_NE(check_source_spec("\x1b[2Jbogus:x").find("\\x1b[2Jbogus:x"), std::string::npos);
}

// A network source's options follow the one spec rule of every spec (bodyd/base/spec_options.h,
// the outputs' too): KEY=VALUE, a trailing '&' allowed, no key twice.
TEST(SourceRegistry, NetworkOptionsFollowTheOneSpecRule) {
  EXPECT_EQ(check_source_spec("vrchat:9001?oscquery=off&name=Me&"), "");
  EXPECT_NE(check_source_spec("vrchat:9001?oscquery").find("option \"oscquery\" is not KEY=VALUE"), std::string::npos);
  EXPECT_NE(check_source_spec("vmc:1?head=A&&left_hand=B").find("is not KEY=VALUE"), std::string::npos);
  const std::string twice = check_source_spec("vmc:1?head=A&head=B");
  EXPECT_NE(twice.find("option \"head\" given twice"), std::string::npos) << twice;
  EXPECT_NE(twice.find("vmc: takes"), std::string::npos) << twice;  // and says which options there are
}

// ---- the device table (device_table.h) ------------------------------------------------------

namespace {

struct RuleLine {
  std::string subsystem;  // "hidraw" or "usb"
  DeviceId id;
  friend bool operator<(const RuleLine& a, const RuleLine& b) {
    return std::tie(a.subsystem, a.id.vendor_id, a.id.product_id) < std::tie(b.subsystem, b.id.vendor_id, b.id.product_id);
  }
  friend bool operator==(const RuleLine&, const RuleLine&) = default;
};

// The value of KEY=="VALUE" in a rule line, or "".
std::string rule_value(const std::string& line, const std::string& key) {
  const std::size_t at = line.find(key + "==\"");
  if (at == std::string::npos) return {};
  const std::size_t start = at + key.size() + 3;
  return line.substr(start, line.find('"', start) - start);
}

std::set<RuleLine> udev_rule_lines(const std::string& text) {
  std::set<RuleLine> out;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    RuleLine r;
    r.subsystem = rule_value(line, "SUBSYSTEM");
    // hidraw's parent USB device is matched with ATTRS, the usb device itself with ATTR.
    const std::string attr = r.subsystem == "hidraw" ? "ATTRS" : "ATTR";
    const std::string vendor = rule_value(line, attr + "{idVendor}"), product = rule_value(line, attr + "{idProduct}");
    EXPECT_EQ(vendor.size(), 4u) << line;
    EXPECT_EQ(product.size(), 4u) << line;
    EXPECT_NE(line.find("TAG+=\"uaccess\""), std::string::npos) << line;
    r.id.vendor_id = static_cast<std::uint16_t>(std::stoul(vendor, nullptr, 16));
    r.id.product_id = static_cast<std::uint16_t>(std::stoul(product, nullptr, 16));
    EXPECT_TRUE(out.insert(r).second) << "twice: " << line;
  }
  return out;
}

std::set<RuleLine> table_rule_lines() {
  std::set<RuleLine> out;
  for (const KnownDevice& d : known_devices()) {
    if (d.hid) out.insert({"hidraw", d.id});
    if (d.usb) out.insert({"usb", d.id});
  }
  return out;
}

}  // namespace

TEST(DeviceTable, TheUdevRuleGrantsExactlyTheTable) {
  std::ifstream in(std::string(BODYD_SOURCE_DIR) + "/packaging/udev/70-bodyd.rules");
  ASSERT_TRUE(in) << "packaging/udev/70-bodyd.rules";
  std::stringstream text;
  text << in.rdbuf();
  const std::set<RuleLine> rule = udev_rule_lines(text.str()), table = table_rule_lines();
  for (const RuleLine& r : table)
    EXPECT_TRUE(rule.count(r)) << "the udev rule lacks SUBSYSTEM==\"" << r.subsystem << "\" for " << std::hex
                               << r.id.vendor_id << ":" << r.id.product_id << " (io/devices/device_table.cpp)";
  for (const RuleLine& r : rule)
    EXPECT_TRUE(table.count(r)) << "the udev rule grants SUBSYSTEM==\"" << r.subsystem << "\" " << std::hex
                                << r.id.vendor_id << ":" << r.id.product_id << ", which the device table lacks";
  EXPECT_EQ(rule.size(), 5u);
}

// The check itself notices a missing or an extra line.
TEST(DeviceTable, TheUdevCheckSeesAMissingAndAnExtraLine) {
  const std::set<RuleLine> one = udev_rule_lines(
      "# comment\n"
      "SUBSYSTEM==\"hidraw\", ATTRS{idVendor}==\"1209\", ATTRS{idProduct}==\"b0d1\", MODE=\"0660\", TAG+=\"uaccess\"\n"
      "SUBSYSTEM==\"usb\", ATTR{idVendor}==\"1209\", ATTR{idProduct}==\"b0d9\", MODE=\"0660\", TAG+=\"uaccess\"\n");
  EXPECT_EQ(one, (std::set<RuleLine>{{"hidraw", {0x1209, 0xB0D1}}, {"usb", {0x1209, 0xB0D9}}}));
  EXPECT_NE(one, table_rule_lines());
}

TEST(DeviceTable, RowsAreUniqueAndDecideTheProtocol) {
  std::set<std::pair<int, int>> ids;
  for (const KnownDevice& d : known_devices()) {
    EXPECT_TRUE(ids.insert({d.id.vendor_id, d.id.product_id}).second) << "an ID twice";
    EXPECT_FALSE(d.name.empty());
    EXPECT_TRUE(d.hid || d.usb);
    EXPECT_EQ(known_device(d.id), &d);
    EXPECT_EQ(device_protocol_of(d.id), d.protocol);
  }
  EXPECT_EQ(device_protocol_of({0x1532, 0x0300}), DeviceProtocol::Hydra);
  EXPECT_EQ(device_protocol_of({0x1234, 0x5678}), DeviceProtocol::BodydReport);  // any ID may stream the report
  EXPECT_EQ(known_device({0x1234, 0x5678}), nullptr);
}

// Every protocol has its row (opener, fake encoder), and the fake encoder's bytes are a report
// the protocol's decoder takes back.
TEST(DeviceTable, EveryProtocolHasARowWhoseFakeTheDecoderReads) {
  std::vector<DeviceProtocol> protocols = {DeviceProtocol::BodydReport, DeviceProtocol::Hydra};
  for (const KnownDevice& d : known_devices()) protocols.push_back(d.protocol);
  for (DeviceProtocol p : protocols) {
    const detail::DeviceProtocolRow& row = detail::device_protocol_row(p);
    EXPECT_EQ(row.protocol, p);
    EXPECT_NE(row.open_hid, nullptr);
    EXPECT_NE(row.encode_fake, nullptr);
  }
  SimulatedDeviceConfig config;
  TrackerSample left, right;
  left.role = Role::LeftHand;
  right.role = Role::RightHand;
  left.valid = right.valid = true;
  left.position_m = Vec3(0.1, 1.0, -0.2);
  right.position_m = Vec3(-0.1, 1.1, -0.3);
  const std::vector<TrackerSample> one{left}, two{left, right};

  config.protocol = DeviceProtocol::BodydReport;
  const std::vector<std::uint8_t> report =
      detail::device_protocol_row(config.protocol).encode_fake({config, one, 7, 1'000'000});
  TrackerReport decoded;
  ASSERT_EQ(decode_tracker_report(report.data(), report.size(), decoded), ReportError::None);
  EXPECT_EQ(decoded.role, Role::LeftHand);
  EXPECT_EQ(decoded.sequence, 7);
  EXPECT_NEAR(decoded.position_m.y(), 1.0, 1e-3);

  config.protocol = DeviceProtocol::Hydra;
  const std::vector<std::uint8_t> hydra =
      detail::device_protocol_row(config.protocol).encode_fake({config, two, 9, 1'000'000});
  HydraReport h;
  ASSERT_EQ(decode_hydra_report(hydra.data(), hydra.size(), config.hydra, h), HydraError::None);
  EXPECT_EQ(h.sequence, 9);
  EXPECT_NEAR(h.controllers[1].position_m.y(), 1.1, 2e-3);
}
