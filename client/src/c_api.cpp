// The C ABI of libbodyd_client.so over bodyd::client::Client. No exception leaves a function.
#define BODYD_CLIENT_BUILDING
#include "bodyd_client.h"

#include "bodyd/client/client.h"

#include <cstring>
#include <new>
#include <string>

using bodyd::client::Client;
using bodyd::client::Received;
namespace protocol = bodyd::protocol;

static_assert(sizeof(bodyd_joint) == 28, "bodyd_joint layout");
static_assert(sizeof(bodyd_pose) == 64 + 28 * BODYD_MAX_JOINTS, "bodyd_pose layout");
static_assert(offsetof(bodyd_pose, root_position_m) == 48 && offsetof(bodyd_pose, joints) == 64, "bodyd_pose layout");
static_assert(sizeof(bodyd_stats) == 40, "bodyd_stats layout");
static_assert(BODYD_MAX_JOINTS == protocol::kMaxJoints, "a decoded pose always fits bodyd_pose");

struct bodyd_client {
  std::unique_ptr<Client> client;
  protocol::PoseMessage pose;  // decode buffer, reused
  std::string error;
};

namespace {

thread_local std::string g_create_error;

int fail(bodyd_client* c, int code, std::string message) {
  c->error = std::move(message);
  return code;
}

const protocol::SkeletonMessage* skeleton_of(const bodyd_client* c) {
  const auto& s = c->client->current_skeleton();
  return s ? &*s : nullptr;
}

}  // namespace

extern "C" {

uint32_t bodyd_client_abi_version(void) { return BODYD_CLIENT_ABI_VERSION; }
size_t bodyd_client_pose_size(void) { return sizeof(bodyd_pose); }

bodyd_client* bodyd_client_create(const char* pose_endpoint, const char* control_endpoint) {
  try {
    bodyd::client::ClientOptions options;
    if (pose_endpoint != nullptr) options.pose_endpoint = pose_endpoint;
    if (control_endpoint != nullptr) options.control_endpoint = control_endpoint;
    auto handle = std::make_unique<bodyd_client>();
    handle->pose.joints.reserve(protocol::kMaxJoints);
    std::string error;
    handle->client = Client::connect(options, error);
    if (!handle->client) {
      g_create_error = std::move(error);
      return nullptr;
    }
    g_create_error.clear();
    return handle.release();
  } catch (const std::exception& e) {
    g_create_error = std::string("bodyd_client_create: ") + e.what();
    return nullptr;
  }
}

void bodyd_client_destroy(bodyd_client* client) { delete client; }

const char* bodyd_client_error(const bodyd_client* client) {
  return client == nullptr ? g_create_error.c_str() : client->error.c_str();
}

int bodyd_client_receive_pose(bodyd_client* c, bodyd_pose* out, int32_t timeout_ms) {
  if (c == nullptr) return BODYD_ERROR_ARGUMENT;
  if (out == nullptr) return fail(c, BODYD_ERROR_ARGUMENT, "bodyd_client_receive_pose: out is NULL");
  try {
    switch (c->client->receive(c->pose, std::chrono::milliseconds(timeout_ms < 0 ? 0 : timeout_ms))) {
      case Received::kTimeout:
        return BODYD_TIMEOUT;
      case Received::kMalformed:
        return fail(c, BODYD_ERROR_MALFORMED, c->client->error());
      case Received::kError:
        return fail(c, BODYD_ERROR, c->client->error());
      case Received::kPose:
        break;
    }
  } catch (const std::exception& e) {
    return fail(c, BODYD_ERROR, e.what());
  }
  const protocol::PoseMessage& p = c->pose;
  out->seq = p.seq;
  out->t_ns = p.t_ns;
  out->publish_t_ns = p.publish_t_ns;
  out->flags = p.flags;
  out->skeleton_id = p.skeleton_id;
  out->joint_count = static_cast<uint32_t>(p.joints.size());
  out->root_joint = p.root_joint;
  out->foot_contact = p.foot_contact;
  out->root_heading_rad = p.root_heading_rad;
  std::memcpy(out->root_position_m, p.root_position_m.data(), sizeof out->root_position_m);
  out->reserved = 0;
  for (std::size_t i = 0; i < p.joints.size(); ++i) {
    std::memcpy(out->joints[i].position_m, p.joints[i].position_m.data(), sizeof(float) * 3);
    std::memcpy(out->joints[i].rotation_xyzw, p.joints[i].rotation_xyzw.data(), sizeof(float) * 4);
  }
  c->error.clear();
  return BODYD_OK;
}

int bodyd_client_request(bodyd_client* c, const char* request_json, char* reply, size_t reply_capacity,
                         size_t* reply_size, int32_t timeout_ms) {
  if (c == nullptr) return BODYD_ERROR_ARGUMENT;
  if (request_json == nullptr) return fail(c, BODYD_ERROR_ARGUMENT, "bodyd_client_request: request_json is NULL");
  try {
    const auto request = nlohmann::json::parse(request_json, nullptr, /*allow_exceptions=*/false);
    if (request.is_discarded()) return fail(c, BODYD_ERROR_ARGUMENT, "bodyd_client_request: request is not valid JSON");
    const auto r = c->client->request(request, std::chrono::milliseconds(timeout_ms < 0 ? 0 : timeout_ms));
    if (r.json.is_null() && !r.ok) return fail(c, BODYD_ERROR, r.error);  // no reply at all
    const std::string text = r.json.dump();
    if (reply_size != nullptr) *reply_size = text.size() + 1;
    if (reply == nullptr || reply_capacity < text.size() + 1) {
      return fail(c, BODYD_ERROR_ARGUMENT, "bodyd_client_request: reply needs " + std::to_string(text.size() + 1) +
                                               " bytes, the buffer has " + std::to_string(reply_capacity));
    }
    std::memcpy(reply, text.c_str(), text.size() + 1);
    if (!r.ok) return fail(c, BODYD_ERROR, r.error);
  } catch (const std::exception& e) {
    return fail(c, BODYD_ERROR, e.what());
  }
  c->error.clear();
  return BODYD_OK;
}

int bodyd_client_fetch_skeleton(bodyd_client* c, int32_t timeout_ms) {
  if (c == nullptr) return BODYD_ERROR_ARGUMENT;
  try {
    protocol::SkeletonMessage s;
    if (protocol::Status st = c->client->skeleton(s, std::chrono::milliseconds(timeout_ms < 0 ? 0 : timeout_ms)); !st) {
      return fail(c, BODYD_ERROR, st.error);
    }
  } catch (const std::exception& e) {
    return fail(c, BODYD_ERROR, e.what());
  }
  c->error.clear();
  return BODYD_OK;
}

uint32_t bodyd_client_skeleton_id(const bodyd_client* c) {
  const auto* s = c ? skeleton_of(c) : nullptr;
  return s ? s->skeleton_id : 0;
}

uint32_t bodyd_client_skeleton_joint_count(const bodyd_client* c) {
  const auto* s = c ? skeleton_of(c) : nullptr;
  return s ? static_cast<uint32_t>(s->names.size()) : 0;
}

const char* bodyd_client_skeleton_joint_name(const bodyd_client* c, uint32_t index) {
  const auto* s = c ? skeleton_of(c) : nullptr;
  return s && index < s->names.size() ? s->names[index].c_str() : nullptr;
}

int bodyd_client_skeleton_joint(const bodyd_client* c, uint32_t index, int32_t* parent, float offset_m[3]) {
  if (c == nullptr) return BODYD_ERROR_ARGUMENT;
  const auto* s = skeleton_of(c);
  if (s == nullptr) return BODYD_ERROR_NO_SKELETON;
  if (index >= s->names.size()) return BODYD_ERROR_ARGUMENT;
  if (parent != nullptr) *parent = s->parents[index];
  if (offset_m != nullptr) std::memcpy(offset_m, s->offsets_m[index].data(), sizeof(float) * 3);
  return BODYD_OK;
}

int bodyd_client_skeleton_rest_rotation(const bodyd_client* c, uint32_t index, float rotation_xyzw[4]) {
  if (c == nullptr || rotation_xyzw == nullptr) return BODYD_ERROR_ARGUMENT;
  const auto* s = skeleton_of(c);
  if (s == nullptr) return BODYD_ERROR_NO_SKELETON;
  if (index >= s->names.size()) return BODYD_ERROR_ARGUMENT;
  if (s->rest_rotations_xyzw.size() != s->names.size()) return BODYD_ERROR_NO_REST_POSE;
  std::memcpy(rotation_xyzw, s->rest_rotations_xyzw[index].data(), sizeof(float) * 4);
  return BODYD_OK;
}

int bodyd_client_stats(const bodyd_client* c, bodyd_stats* out) {
  if (c == nullptr || out == nullptr) return BODYD_ERROR_ARGUMENT;
  const auto& s = c->client->stats();
  *out = bodyd_stats{s.poses, s.dropped, s.malformed, s.skeletons, s.restarts};
  return BODYD_OK;
}

}  // extern "C"
