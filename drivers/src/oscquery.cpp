#include "oscquery.h"

#include <avahi-client/client.h>
#include <avahi-client/publish.h>
#include <avahi-common/alternative.h>
#include <avahi-common/error.h>
#include <avahi-common/malloc.h>
#include <avahi-common/thread-watch.h>
#include <civetweb.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include <mutex>

namespace bodyd::drivers::detail {
namespace {

using nlohmann::json;

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

int send_json(mg_connection* conn, int status, const std::string& body) {
  if (status == 200) {
    mg_send_http_ok(conn, "application/json", static_cast<long long>(body.size()));
    mg_write(conn, body.data(), body.size());
  } else {
    mg_send_http_error(conn, status, "%s", body.c_str());
  }
  return status;
}

class Service final : public OscQueryService {
 public:
  Service(std::string name, std::string osc_ip, int osc_port)
      : name_(std::move(name)), osc_ip_(std::move(osc_ip)), osc_port_(osc_port) {}
  ~Service() override {
    if (poll_) avahi_threaded_poll_stop(poll_);
    if (client_) avahi_client_free(client_);  // frees the entry group too
    if (poll_) avahi_threaded_poll_free(poll_);
    if (ctx_) mg_stop(ctx_);
    if (service_name_) avahi_free(service_name_);
  }

  std::string start_http(const std::string& host) {
    static std::once_flag init;
    std::call_once(init, [] { mg_init_library(0); });
    const std::string ports = (host == "0.0.0.0" ? std::string() : host + ":") + "0";
    const char* options[] = {"listening_ports", ports.c_str(), "num_threads", "2", "request_timeout_ms", "2000",
                             nullptr};
    mg_callbacks callbacks{};
    callbacks.log_message = [](const mg_connection*, const char* message) {
      spdlog::warn("OSCQuery HTTP: {}", message);
      return 1;
    };
    ctx_ = mg_start(&callbacks, this, options);
    if (!ctx_) return "cannot start the OSCQuery HTTP server on " + host + " (CivetWeb mg_start failed)";
    mg_server_port port{};
    if (mg_get_server_ports(ctx_, 1, &port) < 1 || port.port <= 0)
      return "the OSCQuery HTTP server started but reports no port";
    http_port_ = port.port;
    mg_set_request_handler(ctx_, "/", &Service::handle, this);
    return {};
  }

  void start_mdns() {
    poll_ = avahi_threaded_poll_new();
    if (!poll_) {
      set_mdns("cannot create the Avahi poll loop; not announced over mDNS");
      return;
    }
    service_name_ = avahi_strdup((name_ + "-" + std::to_string(osc_port_)).c_str());
    int error = 0;
    client_ = avahi_client_new(avahi_threaded_poll_get(poll_), static_cast<AvahiClientFlags>(0), &Service::on_client,
                               this, &error);
    if (!client_) {
      set_mdns(error == AVAHI_ERR_NO_DAEMON
                   ? "avahi-daemon is not running: OSCQuery is not announced over mDNS, so VRChat will not find "
                     "bodyd by itself; start avahi-daemon, or use VRChat's --osc launch option (docs/vr-apps.md)"
                   : std::string("Avahi client failed (") + avahi_strerror(error) +
                         "): OSCQuery is not announced over mDNS; use VRChat's --osc launch option (docs/vr-apps.md)");
      spdlog::warn("OSCQuery: {}", mdns_state());
      return;
    }
    avahi_threaded_poll_start(poll_);
  }

  int http_port() const override { return http_port_; }
  std::string mdns_state() const override {
    std::lock_guard lock(mutex_);
    return mdns_state_;
  }

 private:
  static int handle(mg_connection* conn, void* self_ptr) {
    auto* self = static_cast<Service*>(self_ptr);
    const mg_request_info* ri = mg_get_request_info(conn);
    if (std::string_view(ri->request_method) != "GET") return send_json(conn, 405, "only GET is served");
    const std::string path = ri->local_uri ? ri->local_uri : "/";
    const std::string query = ri->query_string ? ri->query_string : "";
    if (query == "HOST_INFO")
      return send_json(conn, 200, oscquery_host_info_json(self->name_, self->osc_ip_, self->osc_port_));
    const json* node = find_node(path);
    if (!node) return send_json(conn, 404, "no OSC address " + path);
    if (query.empty()) return send_json(conn, 200, node->dump());
    static constexpr std::string_view kAttributes[] = {"FULL_PATH", "ACCESS", "DESCRIPTION", "CONTENTS", "TYPE"};
    if (std::find(std::begin(kAttributes), std::end(kAttributes), query) == std::end(kAttributes))
      return send_json(conn, 400, "unknown attribute " + query);
    auto it = node->find(query);
    if (it == node->end()) {  // the spec: an attribute the node does not have is "no content"
      mg_printf(conn, "HTTP/1.1 204 No Content\r\nContent-Length: 0\r\nConnection: close\r\n\r\n");
      return 204;
    }
    return send_json(conn, 200, json{{query, *it}}.dump());
  }

  void set_mdns(std::string text) {
    std::lock_guard lock(mutex_);
    mdns_state_ = std::move(text);
  }

  static void on_client(AvahiClient* c, AvahiClientState state, void* self_ptr) {
    auto* self = static_cast<Service*>(self_ptr);
    if (state == AVAHI_CLIENT_S_RUNNING) {
      self->publish(c);
    } else if (state == AVAHI_CLIENT_FAILURE) {
      self->set_mdns(std::string("Avahi client failure: ") + avahi_strerror(avahi_client_errno(c)));
      spdlog::warn("OSCQuery: {}", self->mdns_state());
    }
  }

  static void on_group(AvahiEntryGroup* g, AvahiEntryGroupState state, void* self_ptr) {
    auto* self = static_cast<Service*>(self_ptr);
    if (state == AVAHI_ENTRY_GROUP_ESTABLISHED) {
      self->set_mdns(std::string("announced over mDNS as \"") + self->service_name_ + "\" (_oscjson._tcp port " +
                     std::to_string(self->http_port_) + ", _osc._udp port " + std::to_string(self->osc_port_) + ")");
      spdlog::info("OSCQuery: {}", self->mdns_state());
    } else if (state == AVAHI_ENTRY_GROUP_COLLISION) {
      char* other = avahi_alternative_service_name(self->service_name_);
      avahi_free(self->service_name_);
      self->service_name_ = other;
      avahi_entry_group_reset(g);
      self->add_services(g);
    } else if (state == AVAHI_ENTRY_GROUP_FAILURE) {
      self->set_mdns(std::string("mDNS announcement failed: ") +
                     avahi_strerror(avahi_client_errno(avahi_entry_group_get_client(g))));
      spdlog::warn("OSCQuery: {}", self->mdns_state());
    }
  }

  void publish(AvahiClient* c) {
    if (!group_) group_ = avahi_entry_group_new(c, &Service::on_group, this);
    if (!group_) {
      set_mdns(std::string("cannot create an Avahi entry group: ") + avahi_strerror(avahi_client_errno(c)));
      return;
    }
    if (avahi_entry_group_is_empty(group_)) add_services(group_);
  }

  void add_services(AvahiEntryGroup* g) {
    // IPv4 only: the OSC socket is IPv4.
    int e = avahi_entry_group_add_service(g, AVAHI_IF_UNSPEC, AVAHI_PROTO_INET, static_cast<AvahiPublishFlags>(0),
                                          service_name_, "_oscjson._tcp", nullptr, nullptr,
                                          static_cast<std::uint16_t>(http_port_), nullptr);
    if (e >= 0)
      e = avahi_entry_group_add_service(g, AVAHI_IF_UNSPEC, AVAHI_PROTO_INET, static_cast<AvahiPublishFlags>(0),
                                        service_name_, "_osc._udp", nullptr, nullptr,
                                        static_cast<std::uint16_t>(osc_port_), nullptr);
    if (e >= 0) e = avahi_entry_group_commit(g);
    if (e < 0) {
      set_mdns(std::string("cannot announce over mDNS: ") + avahi_strerror(e));
      spdlog::warn("OSCQuery: {}", mdns_state());
    }
  }

  std::string name_, osc_ip_;
  int osc_port_ = 0;
  int http_port_ = 0;
  mg_context* ctx_ = nullptr;
  AvahiThreadedPoll* poll_ = nullptr;
  AvahiClient* client_ = nullptr;
  AvahiEntryGroup* group_ = nullptr;  // poll thread only
  char* service_name_ = nullptr;
  mutable std::mutex mutex_;
  std::string mdns_state_ = "connecting to avahi-daemon";
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
