// The SlimeVR bridge codec (slimevr_bridge.h): frames and ProtobufMessage, through the protobuf
// classes protoc generates at build time from io/slimevr/slimevr_bridge.proto.
#include "bodyd/io/slimevr/slimevr_bridge.h"

#include "bodyd/base/little_endian.h"
#include "slimevr_bridge.pb.h"

#include <google/protobuf/stubs/logging.h>

#include <limits>

namespace bodyd::drivers::slimevr {

FrameView next_frame(const std::uint8_t* data, std::size_t size, std::size_t max_frame_bytes) {
  FrameView v;
  if (size < kFrameHeaderBytes) return v;
  // uint32 little-endian, counting its own 4 bytes (BridgeTransport.cpp).
  v.declared_bytes = load_le<std::uint32_t>(data);
  if (v.declared_bytes < kFrameHeaderBytes) {
    v.result = FrameResult::TooShort;
    return v;
  }
  if (v.declared_bytes > max_frame_bytes) {
    v.result = FrameResult::TooLong;
    return v;
  }
  if (size < v.declared_bytes) return v;
  v.result = FrameResult::Frame;
  v.frame_bytes = v.declared_bytes;
  v.payload = data + kFrameHeaderBytes;
  v.payload_bytes = v.declared_bytes - kFrameHeaderBytes;
  return v;
}

std::string_view kind_name(Message::Kind kind) {
  switch (kind) {
    case Message::Kind::Empty: return "empty";
    case Message::Kind::Position: return "Position";
    case Message::Kind::UserAction: return "UserAction";
    case Message::Kind::TrackerAdded: return "TrackerAdded";
    case Message::Kind::TrackerStatus: return "TrackerStatus";
    case Message::Kind::Battery: return "Battery";
    case Message::Kind::Version: return "Version";
  }
  return "?";
}

bool decode_message(const std::uint8_t* payload, std::size_t size, Message& out, std::string& error) {
  out = Message{};
  if (size > static_cast<std::size_t>(std::numeric_limits<int>::max())) {
    error = "payload too large";
    return false;
  }
  bodyd_slimevr::ProtobufMessage m;
  // protobuf writes a line to stderr for each string that is not UTF-8: a client could flood
  // the log with them. The bridge counts and rate-limits its own messages instead.
  const google::protobuf::LogSilencer quiet;
  if (!m.ParseFromArray(payload, static_cast<int>(size))) {
    error = "not a ProtobufMessage (" + std::to_string(size) + " bytes)";
    return false;
  }
  switch (m.message_case()) {
    case bodyd_slimevr::ProtobufMessage::kPosition: {
      const auto& p = m.position();
      out.kind = Message::Kind::Position;
      out.tracker_id = p.tracker_id();
      // The driver sends x, y, z together (or none: rotation only).
      out.has_position = p.has_x() && p.has_y() && p.has_z();
      out.x = p.x(), out.y = p.y(), out.z = p.z();
      out.qx = p.qx(), out.qy = p.qy(), out.qz = p.qz(), out.qw = p.qw();
      out.has_data_source = p.has_data_source();
      out.data_source = static_cast<std::int32_t>(p.data_source());
      break;
    }
    case bodyd_slimevr::ProtobufMessage::kUserAction: out.kind = Message::Kind::UserAction; break;
    case bodyd_slimevr::ProtobufMessage::kTrackerAdded: {
      const auto& a = m.tracker_added();
      out.kind = Message::Kind::TrackerAdded;
      out.tracker_id = a.tracker_id();
      out.serial = a.tracker_serial();
      out.name = a.tracker_name();
      out.role = a.tracker_role();
      out.manufacturer = a.manufacturer();
      break;
    }
    case bodyd_slimevr::ProtobufMessage::kTrackerStatus:
      out.kind = Message::Kind::TrackerStatus;
      out.tracker_id = m.tracker_status().tracker_id();
      out.status = static_cast<std::int32_t>(m.tracker_status().status());
      break;
    case bodyd_slimevr::ProtobufMessage::kBattery:
      out.kind = Message::Kind::Battery;
      out.tracker_id = m.battery().tracker_id();
      break;
    case bodyd_slimevr::ProtobufMessage::kVersion:
      out.kind = Message::Kind::Version;
      out.protocol_version = m.version().protocol_version();
      break;
    case bodyd_slimevr::ProtobufMessage::MESSAGE_NOT_SET: out.kind = Message::Kind::Empty; break;
  }
  return true;
}

struct Encoder::Impl {
  bodyd_slimevr::ProtobufMessage message;
  bodyd_slimevr::ProtobufMessage position;  // kept with its Position, so positions reuse it

  static void append(const bodyd_slimevr::ProtobufMessage& m, std::vector<std::uint8_t>& out) {
    const std::size_t size = m.ByteSizeLong();
    const std::uint32_t framed = static_cast<std::uint32_t>(size + kFrameHeaderBytes);
    const std::size_t at = out.size();
    out.resize(at + framed);
    store_le(out.data() + at, framed);
    m.SerializeWithCachedSizesToArray(out.data() + at + kFrameHeaderBytes);
  }
};

Encoder::Encoder() : impl_(std::make_unique<Impl>()) {}
Encoder::~Encoder() = default;

void Encoder::version(std::vector<std::uint8_t>& out, std::int32_t protocol_version) {
  impl_->message.Clear();
  impl_->message.mutable_version()->set_protocol_version(protocol_version);
  Impl::append(impl_->message, out);
}

void Encoder::tracker_added(std::vector<std::uint8_t>& out, std::int32_t id, const std::string& serial,
                            const std::string& name, std::int32_t role, const std::string& manufacturer) {
  impl_->message.Clear();
  auto* a = impl_->message.mutable_tracker_added();
  a->set_tracker_id(id);
  a->set_tracker_serial(serial);
  a->set_tracker_name(name);
  a->set_tracker_role(role);
  a->set_manufacturer(manufacturer);
  Impl::append(impl_->message, out);
}

void Encoder::tracker_status(std::vector<std::uint8_t>& out, std::int32_t id, std::int32_t status) {
  impl_->message.Clear();
  auto* s = impl_->message.mutable_tracker_status();
  s->set_tracker_id(id);
  s->set_status(static_cast<bodyd_slimevr::TrackerStatus::Status>(status));
  Impl::append(impl_->message, out);
}

void Encoder::position(std::vector<std::uint8_t>& out, std::int32_t id, const Vec3& position_m, const Quat& rotation) {
  auto* p = impl_->position.mutable_position();
  p->set_tracker_id(id);
  p->set_x(static_cast<float>(position_m.x()));
  p->set_y(static_cast<float>(position_m.y()));
  p->set_z(static_cast<float>(position_m.z()));
  p->set_qx(static_cast<float>(rotation.x()));
  p->set_qy(static_cast<float>(rotation.y()));
  p->set_qz(static_cast<float>(rotation.z()));
  p->set_qw(static_cast<float>(rotation.w()));
  p->set_data_source(bodyd_slimevr::Position::FULL);
  Impl::append(impl_->position, out);
}

}  // namespace bodyd::drivers::slimevr
