// OSCQuery for the vrchat: input (oscquery.h): the address tree and host info, served by the
// HTTP server of oscquery_http.h and announced by the mDNS of oscquery_mdns.h.
#include "oscquery.h"
#include "oscquery_http.h"
#include "oscquery_mdns.h"

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <functional>
#include <map>
#include <mutex>
#include <thread>
#include <vector>

namespace bodyd::drivers::detail {
namespace {

using nlohmann::json;
using http::HttpResponse;
using http::HttpServer;

// OSCQuery ACCESS values: 0 none, 1 read, 2 write, 3 both. bodyd only receives (VRChat writes to it).
constexpr int kAccessNone = 0;
constexpr int kAccessWrite = 2;

json pose_node(const std::string& part, const char* what) {
  const std::string path = "/tracking/vrsystem/" + part + "/pose";
  return {{"FULL_PATH", "/tracking/vrsystem/" + part},
          {"ACCESS", kAccessNone},
          {"CONTENTS",
           {{"pose",
             {{"FULL_PATH", path},
              {"ACCESS", kAccessWrite},
              {"TYPE", "ffffff"},
              {"DESCRIPTION", std::string(what) +
                                  " pose: position x, y, z (metres), rotation Euler x, y, z (degrees), Unity axes"}}}}}};
}

// The whole tree: / -> tracking -> vrsystem -> {head, leftwrist, rightwrist} -> pose.
const json& tree() {
  static const json t = [] {
    json vrsystem = {{"FULL_PATH", "/tracking/vrsystem"},
                     {"ACCESS", kAccessWrite},
                     {"DESCRIPTION", "headset and wrist poses from VRChat (bodyd reconstructs the body from them)"},
                     {"CONTENTS",
                      {{"head", pose_node("head", "headset")},
                       {"leftwrist", pose_node("leftwrist", "left wrist")},
                       {"rightwrist", pose_node("rightwrist", "right wrist")}}}};
    json tracking = {{"FULL_PATH", "/tracking"}, {"ACCESS", kAccessNone}, {"CONTENTS", {{"vrsystem", vrsystem}}}};
    return json{{"FULL_PATH", "/"},
                {"ACCESS", kAccessNone},
                {"DESCRIPTION", "bodyd: full-body pose from head and hand trackers"},
                {"CONTENTS", {{"tracking", tracking}}}};
  }();
  return t;
}

const json* find_node(const std::string& path) {
  const json* node = &tree();
  if (path.empty() || path == "/") return node;
  std::size_t at = 1;
  while (at <= path.size()) {
    std::size_t slash = path.find('/', at);
    if (slash == std::string::npos) slash = path.size();
    const std::string part = path.substr(at, slash - at);
    at = slash + 1;
    if (part.empty()) continue;  // a trailing or doubled '/'
    auto contents = node->find("CONTENTS");
    if (contents == node->end()) return nullptr;
    auto child = contents->find(part);
    if (child == contents->end()) return nullptr;
    node = &*child;
  }
  return node;
}

class Service final : public OscQueryService {
 public:
  Service(std::string name, std::string osc_ip, int osc_port)
      : name_(std::move(name)), osc_ip_(std::move(osc_ip)), osc_port_(osc_port) {}
  ~Service() override {
    mdns_.reset();  // the announcement first, then the server it announces
    http_.stop();
  }

  std::string start_http(const std::string& host) {
    if (std::string e = http_.start(host); !e.empty()) return "cannot start the OSCQuery HTTP server: " + e;
    http_port_ = http_.port();
    return {};
  }

  void start_mdns() {
    mdns_ = std::make_unique<MdnsAnnouncer>(name_ + "-" + std::to_string(osc_port_), http_port_, osc_port_);
    mdns_->start();
  }

  int http_port() const override { return http_port_; }
  std::string mdns_state() const override { return mdns_ ? mdns_->state() : std::string("connecting to avahi-daemon"); }

 private:
  // OSCQuery answers: read-only, the same for every client (nothing a request can change).
  HttpResponse handle(const std::string& path, const std::string& query) const {
    if (query == "HOST_INFO") return {200, "application/json", oscquery_host_info_json(name_, osc_ip_, osc_port_)};
    const json* node = find_node(path);
    if (!node) return {404, "text/plain", "no OSC address " + path};
    if (query.empty()) return {200, "application/json", node->dump()};
    static constexpr std::string_view kAttributes[] = {"FULL_PATH", "ACCESS", "DESCRIPTION", "CONTENTS", "TYPE"};
    if (std::find(std::begin(kAttributes), std::end(kAttributes), query) == std::end(kAttributes))
      return {400, "text/plain", "unknown attribute " + query};
    auto it = node->find(query);
    if (it == node->end()) return {204, "", ""};  // the spec: an attribute the node does not have is "no content"
    return {200, "application/json", json{{query, *it}}.dump()};
  }

  std::string name_, osc_ip_;
  int osc_port_ = 0;
  int http_port_ = 0;
  HttpServer http_{[this](const std::string& path, const std::string& query) { return handle(path, query); }};
  std::unique_ptr<MdnsAnnouncer> mdns_;
};

}  // namespace

std::string oscquery_tree_json(const std::string& path, bool& out_found) {
  const json* node = find_node(path);
  out_found = node != nullptr;
  return node ? node->dump() : std::string();
}

std::string oscquery_host_info_json(const std::string& name, const std::string& osc_ip, int osc_port) {
  json j = {{"NAME", name},
            {"OSC_PORT", osc_port},
            {"OSC_TRANSPORT", "UDP"},
            {"EXTENSIONS",
             {{"ACCESS", true}, {"DESCRIPTION", true}, {"VALUE", false}, {"RANGE", false}, {"CLIPMODE", false}}}};
  // Without OSC_IP a client sends to the address it reached the HTTP server at (the spec's default).
  if (!osc_ip.empty() && osc_ip != "0.0.0.0") j["OSC_IP"] = osc_ip;
  return j.dump();
}

std::unique_ptr<OscQueryService> OscQueryService::start(const std::string& name, const std::string& host,
                                                        int osc_port, std::string& error) {
  auto s = std::make_unique<Service>(name, host, osc_port);
  if (error = s->start_http(host); !error.empty()) return nullptr;
  s->start_mdns();
  return s;
}

}  // namespace bodyd::drivers::detail
