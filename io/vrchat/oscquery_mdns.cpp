// mDNS for OSCQuery (oscquery.h): the two services announced through the Avahi daemon.
#include "oscquery_mdns.h"

#include <avahi-client/client.h>
#include <avahi-client/publish.h>
#include <avahi-common/alternative.h>
#include <avahi-common/error.h>
#include <avahi-common/malloc.h>
#include <avahi-common/thread-watch.h>
#include <spdlog/spdlog.h>

#include <cstdint>
#include <string>
#include <utility>

namespace bodyd::drivers::detail {

MdnsAnnouncer::MdnsAnnouncer(std::string name, int http_port, int osc_port)
    : name_(std::move(name)), http_port_(http_port), osc_port_(osc_port) {}

MdnsAnnouncer::~MdnsAnnouncer() {
  if (poll_) avahi_threaded_poll_stop(poll_);
  if (client_) avahi_client_free(client_);  // frees the entry group too
  if (poll_) avahi_threaded_poll_free(poll_);
  if (service_name_) avahi_free(service_name_);
}

std::string MdnsAnnouncer::state() const {
  std::lock_guard lock(mutex_);
  return state_;
}

void MdnsAnnouncer::start() {
  poll_ = avahi_threaded_poll_new();
  if (!poll_) {
    set_state("cannot create the Avahi poll loop; not announced over mDNS");
    return;
  }
  service_name_ = avahi_strdup(name_.c_str());
  int error = 0;
  client_ = avahi_client_new(avahi_threaded_poll_get(poll_), static_cast<AvahiClientFlags>(0), &MdnsAnnouncer::on_client,
                             this, &error);
  if (!client_) {
    set_state(error == AVAHI_ERR_NO_DAEMON
                 ? "avahi-daemon is not running: OSCQuery is not announced over mDNS, so VRChat will not find "
                   "bodyd by itself; start avahi-daemon, or use VRChat's --osc launch option (docs/vr-apps.md)"
                 : std::string("Avahi client failed (") + avahi_strerror(error) +
                       "): OSCQuery is not announced over mDNS; use VRChat's --osc launch option (docs/vr-apps.md)");
    spdlog::warn("OSCQuery: {}", state());
    return;
  }
  avahi_threaded_poll_start(poll_);
}

void MdnsAnnouncer::set_state(std::string text) {
  std::lock_guard lock(mutex_);
  state_ = std::move(text);
}

void MdnsAnnouncer::on_client(AvahiClient* c, AvahiClientState state, void* self_ptr) {
  auto* self = static_cast<MdnsAnnouncer*>(self_ptr);
  if (state == AVAHI_CLIENT_S_RUNNING) {
    self->publish(c);
  } else if (state == AVAHI_CLIENT_FAILURE) {
    self->set_state(std::string("Avahi client failure: ") + avahi_strerror(avahi_client_errno(c)));
    spdlog::warn("OSCQuery: {}", self->state());
  }
}

void MdnsAnnouncer::on_group(AvahiEntryGroup* g, AvahiEntryGroupState state, void* self_ptr) {
  auto* self = static_cast<MdnsAnnouncer*>(self_ptr);
  if (state == AVAHI_ENTRY_GROUP_ESTABLISHED) {
    self->set_state(std::string("announced over mDNS as \"") + self->service_name_ + "\" (_oscjson._tcp port " +
                   std::to_string(self->http_port_) + ", _osc._udp port " + std::to_string(self->osc_port_) + ")");
    spdlog::info("OSCQuery: {}", self->state());
  } else if (state == AVAHI_ENTRY_GROUP_COLLISION) {
    char* other = avahi_alternative_service_name(self->service_name_);
    avahi_free(self->service_name_);
    self->service_name_ = other;
    avahi_entry_group_reset(g);
    self->add_services(g);
  } else if (state == AVAHI_ENTRY_GROUP_FAILURE) {
    self->set_state(std::string("mDNS announcement failed: ") +
                   avahi_strerror(avahi_client_errno(avahi_entry_group_get_client(g))));
    spdlog::warn("OSCQuery: {}", self->state());
  }
}

void MdnsAnnouncer::publish(AvahiClient* c) {
  if (!group_) group_ = avahi_entry_group_new(c, &MdnsAnnouncer::on_group, this);
  if (!group_) {
    set_state(std::string("cannot create an Avahi entry group: ") + avahi_strerror(avahi_client_errno(c)));
    return;
  }
  if (avahi_entry_group_is_empty(group_)) add_services(group_);
}

void MdnsAnnouncer::add_services(AvahiEntryGroup* g) {
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
    set_state(std::string("cannot announce over mDNS: ") + avahi_strerror(e));
    spdlog::warn("OSCQuery: {}", state());
  }
}

}  // namespace bodyd::drivers::detail
