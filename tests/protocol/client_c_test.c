/* The C ABI used from C (compiled as C11, not C++):
 *   bodyd_client_c_test POSE_ENDPOINT CONTROL_ENDPOINT COUNT
 * Checks what it can on its own, and prints each pose as a line
 *   POSE seq joint_count root_joint flags foot_contact skeleton_id t_ns px py pz qx qy qz qw
 * (joint 5) for the calling test to compare with the values the publisher sent.
 * Exit status 0 when every check passed; otherwise the failed check is printed. */
#include "bodyd_client.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int failures = 0;
#define CHECK(cond)                                                        \
  do {                                                                     \
    if (!(cond)) {                                                         \
      fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #cond); \
      ++failures;                                                          \
    }                                                                      \
  } while (0)

int main(int argc, char** argv) {
  if (argc != 4) {
    fprintf(stderr, "usage: %s POSE_ENDPOINT CONTROL_ENDPOINT COUNT\n", argv[0]);
    return 2;
  }
  const int count = atoi(argv[3]);
  CHECK(bodyd_client_abi_version() == BODYD_CLIENT_ABI_VERSION);
  CHECK(bodyd_client_pose_size() == sizeof(bodyd_pose));
  CHECK(sizeof(bodyd_pose) == 64 + 28 * BODYD_MAX_JOINTS);

  /* An invalid endpoint: NULL and a reason. */
  bodyd_client* bad = bodyd_client_create("nonsense://nowhere", "");
  CHECK(bad == NULL);
  CHECK(strstr(bodyd_client_error(NULL), "nonsense://nowhere") != NULL);

  bodyd_client* c = bodyd_client_create(argv[1], argv[2]);
  if (c == NULL) {
    fprintf(stderr, "create failed: %s\n", bodyd_client_error(NULL));
    return 1;
  }
  CHECK(strcmp(bodyd_client_error(c), "") == 0);
  CHECK(bodyd_client_receive_pose(c, NULL, 0) == BODYD_ERROR_ARGUMENT);
  CHECK(bodyd_client_receive_pose(NULL, NULL, 0) == BODYD_ERROR_ARGUMENT);
  CHECK(bodyd_client_skeleton_joint(c, 0, NULL, NULL) == BODYD_ERROR_NO_SKELETON ||
        bodyd_client_skeleton_id(c) != 0);

  /* Skeleton over the control socket. */
  int rc = bodyd_client_fetch_skeleton(c, 5000);
  CHECK(rc == BODYD_OK);
  if (rc != BODYD_OK) fprintf(stderr, "fetch_skeleton: %s\n", bodyd_client_error(c));
  CHECK(bodyd_client_skeleton_joint_count(c) == 22);
  CHECK(bodyd_client_skeleton_id(c) != 0);
  const char* hips = bodyd_client_skeleton_joint_name(c, 1);
  CHECK(hips != NULL && strcmp(hips, "Hips") == 0);
  CHECK(bodyd_client_skeleton_joint_name(c, 22) == NULL);
  int32_t parent = 99;
  float offset[3] = {0, 0, 0};
  CHECK(bodyd_client_skeleton_joint(c, 5, &parent, offset) == BODYD_OK);
  CHECK(parent == 4);
  CHECK(offset[1] == 5.0f / 64.0f);
  CHECK(bodyd_client_skeleton_joint(c, 22, &parent, offset) == BODYD_ERROR_ARGUMENT);
  /* The synthetic skeleton is a version-1 one: no rest rotations (issue 20 item 9). */
  float rest[4] = {9, 9, 9, 9};
  CHECK(bodyd_client_skeleton_rest_rotation(c, 5, rest) == BODYD_ERROR_NO_REST_POSE);
  CHECK(rest[0] == 9 && rest[3] == 9);
  CHECK(bodyd_client_skeleton_rest_rotation(c, 5, NULL) == BODYD_ERROR_ARGUMENT);

  /* A request the server refuses: BODYD_ERROR, reply copied, error set. */
  char reply[512];
  size_t needed = 0;
  CHECK(bodyd_client_request(c, "{\"cmd\":\"no-such-command\"}", reply, sizeof reply, &needed, 5000) == BODYD_ERROR);
  CHECK(strstr(reply, "\"ok\":false") != NULL);
  CHECK(strstr(bodyd_client_error(c), "unknown command") != NULL);
  CHECK(needed == strlen(reply) + 1);
  /* A reply that does not fit. */
  CHECK(bodyd_client_request(c, "{\"cmd\":\"skeleton\"}", reply, 8, &needed, 5000) == BODYD_ERROR_ARGUMENT);
  CHECK(needed > 8);
  /* Not JSON. */
  CHECK(bodyd_client_request(c, "{cmd", reply, sizeof reply, NULL, 5000) == BODYD_ERROR_ARGUMENT);

  /* Poses. */
  bodyd_pose* pose = (bodyd_pose*)calloc(1, sizeof(bodyd_pose));
  int received = 0;
  int timeouts = 0;
  uint64_t last_seq = 0;
  while (received < count && timeouts < 100) {
    rc = bodyd_client_receive_pose(c, pose, 100);
    if (rc == BODYD_TIMEOUT) {
      ++timeouts;
      continue;
    }
    CHECK(rc == BODYD_OK);
    if (rc != BODYD_OK) {
      fprintf(stderr, "receive: %d %s\n", rc, bodyd_client_error(c));
      break;
    }
    CHECK(received == 0 || pose->seq > last_seq);
    last_seq = pose->seq;
    CHECK(pose->joint_count == 22);
    CHECK(pose->root_joint == 1);
    CHECK(pose->skeleton_id == bodyd_client_skeleton_id(c));
    CHECK(pose->root_position_m[0] == pose->joints[1].position_m[0]);
    const bodyd_joint* j = &pose->joints[5];
    printf("POSE %llu %u %u %u %u %u %lld %.9g %.9g %.9g %.9g %.9g %.9g %.9g\n", (unsigned long long)pose->seq,
           pose->joint_count, pose->root_joint, pose->flags, pose->foot_contact, pose->skeleton_id,
           (long long)pose->t_ns, j->position_m[0], j->position_m[1], j->position_m[2], j->rotation_xyzw[0],
           j->rotation_xyzw[1], j->rotation_xyzw[2], j->rotation_xyzw[3]);
    ++received;
  }
  CHECK(received == count);
  bodyd_stats stats;
  CHECK(bodyd_client_stats(c, &stats) == BODYD_OK);
  CHECK(stats.poses == (uint64_t)received);
  CHECK(stats.malformed == 0);
  free(pose);
  bodyd_client_destroy(c);
  bodyd_client_destroy(NULL);
  if (failures) fprintf(stderr, "%d checks failed\n", failures);
  return failures ? 1 : 0;
}
