// mDNS for OSCQuery (oscquery.h): announces `_oscjson._tcp` (the HTTP port) and `_osc._udp`
// (the OSC port) under one service name through the Avahi daemon, best effort: state() says
// whether it worked (and the log, once). Internal to vrchat/.
#pragma once

#include <avahi-client/client.h>
#include <avahi-client/publish.h>
#include <avahi-common/thread-watch.h>

#include <mutex>
#include <string>

namespace bodyd::drivers::detail {

class MdnsAnnouncer {
 public:
  MdnsAnnouncer(std::string name, int http_port, int osc_port);
  ~MdnsAnnouncer();
  MdnsAnnouncer(const MdnsAnnouncer&) = delete;
  MdnsAnnouncer& operator=(const MdnsAnnouncer&) = delete;

  // Connects to avahi-daemon and announces from its poll thread; never fails (state() says).
  void start();
  [[nodiscard]] std::string state() const;

 private:
  void set_state(std::string text);
  static void on_client(AvahiClient* c, AvahiClientState state, void* self_ptr);
  static void on_group(AvahiEntryGroup* g, AvahiEntryGroupState state, void* self_ptr);
  void publish(AvahiClient* c);
  void add_services(AvahiEntryGroup* g);

  std::string name_;
  int http_port_ = 0;
  int osc_port_ = 0;
  AvahiThreadedPoll* poll_ = nullptr;
  AvahiClient* client_ = nullptr;
  AvahiEntryGroup* group_ = nullptr;  // poll thread only
  char* service_name_ = nullptr;
  mutable std::mutex mutex_;
  std::string state_ = "connecting to avahi-daemon";
};

}  // namespace bodyd::drivers::detail
