#include "bodyd/client/client.h"

#include <fmt/format.h>

#include <zmq.hpp>

#include <algorithm>
#include <charconv>
#include <cstdlib>

namespace bodyd::client {

using protocol::PoseMessage;
using protocol::SkeletonMessage;
using protocol::Status;
using Clock = std::chrono::steady_clock;

struct Client::Impl {
  ClientOptions options;
  zmq::context_t context{1};
  zmq::socket_t sub{context, zmq::socket_type::sub};
  std::optional<zmq::socket_t> control;  // recreated after a timed-out request (REQ state machine)
  std::string error;
  std::optional<SkeletonMessage> skeleton;
  ClientStats stats;
  std::optional<std::uint64_t> last_seq;
  zmq::message_t topic;
  zmq::message_t frame;

  Impl() = default;

  // CURVE's keys on `socket` before it connects, when the options give a server key.
  void apply_curve(zmq::socket_t& socket) const {
    if (options.curve_server_key.empty()) return;
    socket.set(zmq::sockopt::curve_serverkey, options.curve_server_key);
    socket.set(zmq::sockopt::curve_publickey, options.curve_public_key);
    socket.set(zmq::sockopt::curve_secretkey, options.curve_secret_key);
  }

  bool open_control(std::string& out_error) {
    control.reset();
    if (options.control_endpoint.empty()) return true;
    try {
      control.emplace(context, zmq::socket_type::req);
      control->set(zmq::sockopt::linger, 0);
      apply_curve(*control);
      control->connect(options.control_endpoint);
    } catch (const zmq::error_t& e) {
      control.reset();
      out_error = fmt::format("control endpoint \"{}\": {} (expected e.g. ipc:///tmp/bodyd/control or "
                              "tcp://127.0.0.1:5556)", options.control_endpoint, e.what());
      return false;
    }
    return true;
  }

  void note_seq(std::uint64_t seq) {
    if (last_seq) {
      if (seq > *last_seq) stats.dropped += seq - *last_seq - 1;
      else ++stats.restarts;
    }
    last_seq = seq;
  }
};

Client::Client(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Client::~Client() = default;

std::unique_ptr<Client> Client::connect(const ClientOptions& options, std::string& error) {
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  ClientOptions& o = impl->options;
  if (!o.curve_server_key.empty()) {
    if (o.curve_secret_key.empty()) {
      // No key pair of our own: a fresh one.
      char pub[41] = {}, sec[41] = {};
      if (zmq_curve_keypair(pub, sec) != 0) {
        error = fmt::format("cannot make a CURVE key pair: {}", zmq_strerror(zmq_errno()));
        return nullptr;
      }
      o.curve_public_key = pub;
      o.curve_secret_key = sec;
    } else if (o.curve_public_key.empty()) {
      char pub[41] = {};
      if (o.curve_secret_key.size() != 40 || zmq_curve_public(pub, o.curve_secret_key.c_str()) != 0) {
        error = "the CURVE secret key is not 40 characters of Z85 text";
        return nullptr;
      }
      o.curve_public_key = pub;
    }
  }
  try {
    impl->sub.set(zmq::sockopt::linger, 0);
    if (!options.pose_endpoint.empty()) {
      impl->sub.set(zmq::sockopt::rcvhwm, std::max(1, options.receive_hwm));
      impl->sub.set(zmq::sockopt::subscribe, protocol::kPoseTopic);
      impl->sub.set(zmq::sockopt::subscribe, protocol::kSkeletonTopic);
      impl->apply_curve(impl->sub);
      impl->sub.connect(options.pose_endpoint);
    }
  } catch (const zmq::error_t& e) {
    error = fmt::format("pose endpoint \"{}\": {} (expected e.g. ipc:///tmp/bodyd/pose or tcp://127.0.0.1:5555)",
                        options.pose_endpoint, e.what());
    return nullptr;
  }
  if (!impl->open_control(error)) return nullptr;
  return std::unique_ptr<Client>(new Client(std::move(impl)));
}

Received Client::receive(PoseMessage& out, std::chrono::milliseconds timeout) {
  Impl& m = *impl_;
  if (m.options.pose_endpoint.empty()) {
    m.error = "no pose endpoint configured";
    return Received::kError;
  }
  const auto deadline = Clock::now() + timeout;
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
    try {
      m.sub.set(zmq::sockopt::rcvtimeo, static_cast<int>(std::max<std::int64_t>(0, left.count())));
      if (!m.sub.recv(m.topic, zmq::recv_flags::none)) return Received::kTimeout;
      // The frames of a multipart message arrive together: the rest is already here.
      int frames = 1;
      if (m.sub.get(zmq::sockopt::rcvmore)) {
        if (m.sub.recv(m.frame, zmq::recv_flags::dontwait)) ++frames;
        while (m.sub.get(zmq::sockopt::rcvmore)) {
          zmq::message_t extra;
          if (!m.sub.recv(extra, zmq::recv_flags::dontwait)) break;
          ++frames;
        }
      }
      if (frames != 2) {
        ++m.stats.malformed;
        m.error = fmt::format("message with {} frames (expected 2: topic, message)", frames);
        return Received::kMalformed;
      }
    } catch (const zmq::error_t& e) {
      m.error = fmt::format("receiving from \"{}\": {}", m.options.pose_endpoint, e.what());
      return Received::kError;
    }
    const std::string_view topic(static_cast<const char*>(m.topic.data()), m.topic.size());
    const auto bytes = protocol::as_bytes(m.frame.data(), m.frame.size());
    if (topic == protocol::kPoseTopic) {
      if (Status s = protocol::decode_pose(bytes, out); !s) {
        ++m.stats.malformed;
        m.error = std::move(s.error);
        return Received::kMalformed;
      }
      ++m.stats.poses;
      m.note_seq(out.seq);
      return Received::kPose;
    }
    if (topic == protocol::kSkeletonTopic) {
      SkeletonMessage skeleton;
      if (Status s = protocol::decode_skeleton(bytes, skeleton); !s) {
        ++m.stats.malformed;
        m.error = std::move(s.error);
        return Received::kMalformed;
      }
      ++m.stats.skeletons;
      m.skeleton = std::move(skeleton);
    }
    // Skeletons and unknown topics (a later protocol's) do not end the wait.
  }
}

const std::string& Client::error() const { return impl_->error; }
const std::optional<SkeletonMessage>& Client::current_skeleton() const { return impl_->skeleton; }
const ClientStats& Client::stats() const { return impl_->stats; }

ControlReply Client::request(const nlohmann::json& request) {
  return this->request(request, impl_->options.control_timeout);
}

ControlReply Client::request(const nlohmann::json& request, std::chrono::milliseconds timeout) {
  Impl& m = *impl_;
  ControlReply reply;
  const auto failed = [&](std::string what) {
    reply.ok = false;
    reply.error = std::move(what);
    m.error = reply.error;
    return reply;
  };
  if (!m.control) {
    if (m.options.control_endpoint.empty()) return failed("no control endpoint configured");
    std::string error;
    if (!m.open_control(error)) return failed(error);
  }
  try {
    const std::string text = request.dump();
    m.control->send(zmq::buffer(text), zmq::send_flags::none);
    m.control->set(zmq::sockopt::rcvtimeo, static_cast<int>(std::max<std::int64_t>(0, timeout.count())));
    zmq::message_t msg;
    if (!m.control->recv(msg, zmq::recv_flags::none)) {
      m.control.reset();  // a REQ socket waiting for a reply cannot send again: start over
      reply.timed_out = true;
      return failed(fmt::format("no reply from control endpoint \"{}\" within {} ms (is bodyd running?)",
                                m.options.control_endpoint, timeout.count()));
    }
    reply.json = nlohmann::json::parse(msg.to_string_view(), nullptr, /*allow_exceptions=*/false);
  } catch (const zmq::error_t& e) {
    m.control.reset();
    return failed(fmt::format("control endpoint \"{}\": {}", m.options.control_endpoint, e.what()));
  } catch (const nlohmann::json::exception& e) {  // dump() of invalid UTF-8 strings
    return failed(fmt::format("request cannot be sent as JSON: {}", e.what()));
  }
  if (reply.json.is_discarded() || !reply.json.is_object()) {
    return failed("control reply is not a JSON object");
  }
  const auto ok = reply.json.find("ok");
  if (ok == reply.json.end() || !ok->is_boolean()) return failed("control reply has no boolean \"ok\" field");
  reply.ok = ok->get<bool>();
  if (!reply.ok) {
    const auto err = reply.json.find("error");
    reply.error = err != reply.json.end() && err->is_string() ? err->get<std::string>()
                                                              : std::string("request failed (no \"error\" text)");
    m.error = reply.error;
  }
  return reply;
}

Status Client::skeleton(SkeletonMessage& out) { return skeleton(out, impl_->options.control_timeout); }

Status Client::skeleton(SkeletonMessage& out, std::chrono::milliseconds timeout) {
  ControlReply reply = request({{"cmd", "skeleton"}}, timeout);
  if (!reply.ok) return Status{"skeleton request: " + reply.error};
  // The fields may sit at the top level of the reply or under "skeleton".
  const nlohmann::json& body =
      reply.json.contains("skeleton") && reply.json["skeleton"].is_object() ? reply.json["skeleton"] : reply.json;
  if (Status s = skeleton_from_json(body, out); !s) return Status{"skeleton reply: " + s.error};
  impl_->skeleton = out;
  return {};
}

nlohmann::json skeleton_to_json(const SkeletonMessage& s) {
  nlohmann::json offsets = nlohmann::json::array();
  for (const auto& o : s.offsets_m) offsets.push_back({o[0], o[1], o[2]});
  nlohmann::json j = {{"skeleton_id", s.skeleton_id}, {"names", s.names}, {"parents", s.parents}, {"offsets_m", offsets}};
  if (!s.rest_rotations_xyzw.empty()) {
    nlohmann::json rest = nlohmann::json::array();
    for (const auto& q : s.rest_rotations_xyzw) rest.push_back({q[0], q[1], q[2], q[3]});
    j["rest_rotations_xyzw"] = rest;
  }
  return j;
}

Status skeleton_from_json(const nlohmann::json& j, SkeletonMessage& out) {
  if (!j.is_object()) return Status{"not a JSON object"};
  for (const char* key : {"skeleton_id", "names", "parents", "offsets_m"}) {
    if (!j.contains(key)) return Status{fmt::format("missing field \"{}\"", key)};
  }
  const auto& names = j["names"];
  const auto& parents = j["parents"];
  const auto& offsets = j["offsets_m"];
  const auto& json_id = j["skeleton_id"];
  if (!json_id.is_number_integer() || json_id.get<std::int64_t>() < 0 || json_id.get<std::int64_t>() > 0xFFFFFFFFll) {
    return Status{"\"skeleton_id\" is not a 32-bit unsigned integer"};
  }
  if (!names.is_array() || !parents.is_array() || !offsets.is_array()) {
    return Status{"\"names\", \"parents\" and \"offsets_m\" must be arrays"};
  }
  if (names.size() != parents.size() || names.size() != offsets.size()) {
    return Status{fmt::format("{} names, {} parents, {} offsets_m: the counts must match", names.size(),
                              parents.size(), offsets.size())};
  }
  if (names.size() > protocol::kMaxJoints) {
    return Status{fmt::format("{} joints exceeds the maximum {}", names.size(), protocol::kMaxJoints)};
  }
  SkeletonMessage s;
  s.skeleton_id = j["skeleton_id"].get<std::uint32_t>();
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (!names[i].is_string()) return Status{fmt::format("names[{}] is not a string", i)};
    if (!parents[i].is_number_integer() || parents[i].get<std::int64_t>() < -1 ||
        parents[i].get<std::int64_t>() >= static_cast<std::int64_t>(protocol::kMaxJoints)) {
      return Status{fmt::format("parents[{}] is not an integer in -1..{}", i, protocol::kMaxJoints - 1)};
    }
    const auto& o = offsets[i];
    if (!o.is_array() || o.size() != 3 || !o[0].is_number() || !o[1].is_number() || !o[2].is_number()) {
      return Status{fmt::format("offsets_m[{}] is not an array of 3 numbers", i)};
    }
    s.names.push_back(names[i].get<std::string>());
    s.parents.push_back(static_cast<std::int16_t>(parents[i].get<std::int64_t>()));
    s.offsets_m.push_back({o[0].get<float>(), o[1].get<float>(), o[2].get<float>()});
  }
  // Optional (docs/protocol.md): absent for a skeleton without a rest pose.
  if (j.contains("rest_rotations_xyzw")) {
    const auto& rest = j["rest_rotations_xyzw"];
    if (!rest.is_array() || rest.size() != names.size())
      return Status{fmt::format("\"rest_rotations_xyzw\" must be an array of {} quaternions", names.size())};
    for (std::size_t i = 0; i < rest.size(); ++i) {
      const auto& q = rest[i];
      if (!q.is_array() || q.size() != 4 || !q[0].is_number() || !q[1].is_number() || !q[2].is_number() ||
          !q[3].is_number())
        return Status{fmt::format("rest_rotations_xyzw[{}] is not an array of 4 numbers", i)};
      s.rest_rotations_xyzw.push_back({q[0].get<float>(), q[1].get<float>(), q[2].get<float>(), q[3].get<float>()});
    }
  }
  if (Status v = protocol::validate_skeleton(s); !v) return v;
  const std::uint32_t id = protocol::skeleton_id_of(s);
  if (id != s.skeleton_id) {
    return Status{fmt::format("skeleton_id {} does not match the skeleton's hash {} (docs/protocol.md)",
                              s.skeleton_id, id)};
  }
  out = std::move(s);
  return {};
}

namespace {

// The float as the double with the shortest decimal form that still reads back as that float
// (0.031f prints as 0.031, not 0.03099999949336052).
double shortest(float v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  *r.ptr = '\0';
  return std::strtod(buf, nullptr);
}

template <std::size_t N>
nlohmann::ordered_json shortest(const std::array<float, N>& v) {
  nlohmann::ordered_json a = nlohmann::ordered_json::array();
  for (float x : v) a.push_back(shortest(x));
  return a;
}

}  // namespace

nlohmann::ordered_json pose_to_json(const PoseMessage& pose, const SkeletonMessage* skeleton, bool with_rotations) {
  using Json = nlohmann::ordered_json;
  const bool named = skeleton != nullptr && skeleton->skeleton_id == pose.skeleton_id &&
                     skeleton->names.size() == pose.joints.size();
  Json j;
  j["seq"] = pose.seq;
  j["t_ns"] = pose.t_ns;
  j["publish_t_ns"] = pose.publish_t_ns;
  j["flags"] = pose.flags;
  j["skeleton_id"] = pose.skeleton_id;
  j["foot_contact"] = {(pose.foot_contact & protocol::kFootContactLeft) != 0,
                       (pose.foot_contact & protocol::kFootContactRight) != 0};
  Json root;
  root["joint"] = pose.root_joint == protocol::kNoRootJoint ? Json(nullptr) : Json(pose.root_joint);
  root["position_m"] = shortest(pose.root_position_m);
  root["heading_rad"] = shortest(pose.root_heading_rad);
  j["root"] = std::move(root);
  Json positions = named ? Json::object() : Json::array();
  Json rotations = named ? Json::object() : Json::array();
  for (std::size_t i = 0; i < pose.joints.size(); ++i) {
    if (named) {
      positions[skeleton->names[i]] = shortest(pose.joints[i].position_m);
      if (with_rotations) rotations[skeleton->names[i]] = shortest(pose.joints[i].rotation_xyzw);
    } else {
      positions.push_back(shortest(pose.joints[i].position_m));
      if (with_rotations) rotations.push_back(shortest(pose.joints[i].rotation_xyzw));
    }
  }
  j["joints"] = std::move(positions);
  if (with_rotations) j["rotations_xyzw"] = std::move(rotations);
  return j;
}

}  // namespace bodyd::client
