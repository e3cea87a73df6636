/* bodyd client, C ABI (libbodyd_client.so).
 *
 * Receives bodyd's pose stream (docs/protocol.md) and talks to its control socket
 * (docs/control.md) from C, C#/Unity (P/Invoke), Python ctypes and anything else that can
 * call C. The header uses only C types; every struct has a fixed, padding-free layout
 * (sizes below) so it can be declared field by field in another language.
 *
 * Threading: one handle per thread (or serialise calls on a handle). Different handles are
 * independent.
 * Strings returned by the library belong to the handle and stay valid until the next call
 * on that handle (or until it is destroyed).
 *
 * Return codes: BODYD_OK (0) and BODYD_TIMEOUT (1) are normal outcomes; negative values are
 * errors, explained by bodyd_client_error().
 */
#ifndef BODYD_CLIENT_H
#define BODYD_CLIENT_H

#include <stddef.h>
#include <stdint.h>

#if defined(BODYD_CLIENT_BUILDING)
#define BODYD_API __attribute__((visibility("default")))
#else
#define BODYD_API
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* Increases whenever a struct or a function signature of this header changes. */
#define BODYD_CLIENT_ABI_VERSION 1

#define BODYD_MAX_JOINTS 128

/* Flag bits of bodyd_pose.flags (docs/protocol.md). */
#define BODYD_FLAG_HEAD_VALID 0x01u
#define BODYD_FLAG_LEFT_HAND_VALID 0x02u
#define BODYD_FLAG_RIGHT_HAND_VALID 0x04u
#define BODYD_FLAG_HEIGHT_CALIBRATED 0x08u
#define BODYD_FLAG_OFFSETS_CALIBRATED 0x10u
/* Bits of bodyd_pose.foot_contact. */
#define BODYD_FOOT_CONTACT_LEFT 0x01u
#define BODYD_FOOT_CONTACT_RIGHT 0x02u
/* bodyd_pose.root_joint when the pose has no root joint. */
#define BODYD_NO_ROOT_JOINT 0xFFFFu

/* Return codes. */
#define BODYD_OK 0
#define BODYD_TIMEOUT 1            /* nothing arrived in time; not an error */
#define BODYD_ERROR (-1)           /* socket or request failure, see bodyd_client_error() */
#define BODYD_ERROR_MALFORMED (-2) /* a message could not be decoded and was skipped; keep receiving */
#define BODYD_ERROR_ARGUMENT (-3)  /* a NULL handle or pointer, an index out of range, a buffer too small */
#define BODYD_ERROR_NO_SKELETON (-4) /* no skeleton known yet */
#define BODYD_ERROR_NO_REST_POSE (-5) /* the skeleton carries no rest rotations (a version-1 skeleton) */

/* One joint's global pose: metres, unit quaternion (x, y, z, w), +Y up. 28 bytes. */
typedef struct bodyd_joint {
  float position_m[3];
  float rotation_xyzw[4];
} bodyd_joint;

/* A pose (topic "pose"). 64 + 28 * BODYD_MAX_JOINTS = 3648 bytes; joints[joint_count..]
 * are left unchanged. Times: nanoseconds; publish_t_ns of the daemon's CLOCK_MONOTONIC, t_ns of
 * the samples' time base (the same clock for live sources; docs/protocol.md). */
typedef struct bodyd_pose {
  uint64_t seq;                /* offset 0: +1 per published pose; gaps are dropped poses */
  int64_t t_ns;                /* 8: the time the pose is for: its head sample's t_ns */
  int64_t publish_t_ns;        /* 16: when the daemon published it */
  uint32_t flags;              /* 24: BODYD_FLAG_* bits */
  uint32_t skeleton_id;        /* 28: id of the skeleton the joints follow */
  uint32_t joint_count;        /* 32: valid entries of joints[] */
  uint32_t root_joint;         /* 36: index of the root (Hips) joint, or BODYD_NO_ROOT_JOINT */
  uint32_t foot_contact;       /* 40: BODYD_FOOT_CONTACT_* bits */
  float root_heading_rad;      /* 44: root yaw about +Y (atan2 of its +Z axis' x and z) */
  float root_position_m[3];    /* 48: root global position */
  uint32_t reserved;           /* 60: 0 */
  bodyd_joint joints[BODYD_MAX_JOINTS]; /* 64 */
} bodyd_pose;

/* Counters since the handle was created. 40 bytes. */
typedef struct bodyd_stats {
  uint64_t poses;     /* poses received */
  uint64_t dropped;   /* poses missing between received ones (seq gaps) */
  uint64_t malformed; /* messages that could not be decoded */
  uint64_t skeletons; /* skeleton messages received on the stream */
  uint64_t restarts;  /* times seq went backwards (the daemon restarted) */
} bodyd_stats;

typedef struct bodyd_client bodyd_client; /* opaque */

/* BODYD_CLIENT_ABI_VERSION of the loaded library, and sizeof(bodyd_pose) in it: check both
 * before use when loading the library dynamically. */
BODYD_API uint32_t bodyd_client_abi_version(void);
BODYD_API size_t bodyd_client_pose_size(void);

/* Connects to the daemon's pose endpoint (NULL: "ipc:///tmp/bodyd/pose") and control
 * endpoint (NULL: "ipc:///tmp/bodyd/control"; "" for none). Succeeds whether or not the
 * daemon runs (ZeroMQ connects when it appears). NULL on an invalid endpoint: then
 * bodyd_client_error(NULL) says why. */
BODYD_API bodyd_client* bodyd_client_create(const char* pose_endpoint, const char* control_endpoint);
BODYD_API void bodyd_client_destroy(bodyd_client* client);

/* Why the last call on `client` failed (never NULL; "" when nothing failed). With NULL: why
 * this thread's last bodyd_client_create failed. */
BODYD_API const char* bodyd_client_error(const bodyd_client* client);

/* Waits up to timeout_ms (0: only what is queued) for the next pose and writes it to *out.
 * Returns BODYD_OK, BODYD_TIMEOUT, BODYD_ERROR_MALFORMED (skipped; call again) or BODYD_ERROR. */
BODYD_API int bodyd_client_receive_pose(bodyd_client* client, bodyd_pose* out, int32_t timeout_ms);

/* Sends a JSON request (e.g. "{\"cmd\":\"status\"}") to the control socket and copies the JSON
 * reply, NUL-terminated, into reply (reply_capacity bytes). BODYD_OK when the reply says
 * "ok": true; BODYD_ERROR when it says false (the reply is still copied) or no reply came;
 * BODYD_ERROR_ARGUMENT when the reply does not fit (*reply_size, if given, gets the size needed
 * including the NUL). */
BODYD_API int bodyd_client_request(bodyd_client* client, const char* request_json, char* reply,
                                   size_t reply_capacity, size_t* reply_size, int32_t timeout_ms);

/* Asks the control socket for the skeleton; on BODYD_OK it becomes the current skeleton. */
BODYD_API int bodyd_client_fetch_skeleton(bodyd_client* client, int32_t timeout_ms);

/* The current skeleton: the newest received on the stream or by bodyd_client_fetch_skeleton.
 * skeleton_id is 0 and joint_count 0 while none is known. */
BODYD_API uint32_t bodyd_client_skeleton_id(const bodyd_client* client);
BODYD_API uint32_t bodyd_client_skeleton_joint_count(const bodyd_client* client);
/* Joint `index`'s name (UTF-8), or NULL when out of range. */
BODYD_API const char* bodyd_client_skeleton_joint_name(const bodyd_client* client, uint32_t index);
/* Joint `index`'s parent index (-1 for the root) and rest offset (metres, parent frame). */
BODYD_API int bodyd_client_skeleton_joint(const bodyd_client* client, uint32_t index, int32_t* parent,
                                          float offset_m[3]);

/* Joint `index`'s rest rotation relative to its parent, quaternion (x, y, z, w), unit length
 * (docs/protocol.md, "Rest pose"): forward kinematics of the rest offsets and rest rotations
 * gives the skeleton's reference T-pose, which retargeting to an avatar needs. BODYD_OK;
 * BODYD_ERROR_NO_SKELETON while no skeleton is known; BODYD_ERROR_NO_REST_POSE when the
 * skeleton has none (version 1; rotation_xyzw is left unchanged); BODYD_ERROR_ARGUMENT for a
 * NULL pointer or an index out of range. */
BODYD_API int bodyd_client_skeleton_rest_rotation(const bodyd_client* client, uint32_t index, float rotation_xyzw[4]);

BODYD_API int bodyd_client_stats(const bodyd_client* client, bodyd_stats* out);

#ifdef __cplusplus
}
#endif

#endif /* BODYD_CLIENT_H */
