// Internal: the OSCQuery side of the vrchat: input (docs/vr-apps.md "OSCQuery").
//
// OSCQuery (Vidvox OSCQueryProposal, github.com/Vidvox/OSCQueryProposal) lets VRChat find an
// app that wants its tracking data: the app serves its OSC address tree as JSON over HTTP
// (a small poll()-based server of its own, oscquery_http.h) and announces two mDNS services, `_oscjson._tcp` (the HTTP port) and
// `_osc._udp` (the OSC port), through the Avahi daemon. VRChat sends /tracking/vrsystem/* to
// an app whose tree contains /tracking/vrsystem (vrchat-community/osc wiki, "OSCQuery").
//
// HTTP answers (JSON, Content-Type application/json; errors as plain text):
//   GET /?HOST_INFO              {"NAME", "OSC_PORT", "OSC_TRANSPORT": "UDP", "OSC_IP" (unless bound
//                                to every interface), "EXTENSIONS": {...}}
//   GET /PATH                    the node at PATH: {"FULL_PATH", "ACCESS", "DESCRIPTION", "CONTENTS" | "TYPE"}
//   GET /PATH?ATTRIBUTE          {"ATTRIBUTE": value} for FULL_PATH, ACCESS, DESCRIPTION, CONTENTS, TYPE
//   anything else                404 (unknown path), 400 (unknown attribute), 405 (not GET or HEAD),
//                                403 (a Host that is not an IP address, localhost or NAME.local)
// Read-only: no request changes anything. One request per connection; the limits (header
// timeout, connection caps, back-off when out of descriptors) are in oscquery_http.h; the mDNS announcement is oscquery_mdns.cpp.
//
// mDNS is best effort: without a running avahi-daemon the HTTP endpoint still answers and
// mdns_state() (and the log, once) says so; the launch-option route then works.
#pragma once

#include <memory>
#include <string>

namespace bodyd::drivers::detail {

// The address tree and host info as JSON text (pure; tested without a server).
[[nodiscard]] std::string oscquery_tree_json(const std::string& path, bool& out_found);
[[nodiscard]] std::string oscquery_host_info_json(const std::string& name, const std::string& osc_ip, int osc_port);

class OscQueryService {
 public:
  // Serves HTTP on `host` (a free port; "0.0.0.0": every interface) and announces it.
  // nullptr and `error` when the HTTP server cannot start.
  [[nodiscard]] static std::unique_ptr<OscQueryService> start(const std::string& name, const std::string& host,
                                                             int osc_port, std::string& error);
  virtual ~OscQueryService() = default;
  [[nodiscard]] virtual int http_port() const = 0;
  [[nodiscard]] virtual std::string mdns_state() const = 0;
};

}  // namespace bodyd::drivers::detail
