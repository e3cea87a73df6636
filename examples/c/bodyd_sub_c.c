/* Minimal C subscriber over libbodyd_client.so (client/include/bodyd_client.h).
 *   bodyd_sub_c [POSE_ENDPOINT [CONTROL_ENDPOINT]]
 * Prints the Hips position of every pose until interrupted. */
#include "bodyd_client.h"

#include <stdio.h>
#include <stdlib.h>

int main(int argc, char** argv) {
  const char* pose_endpoint = argc > 1 ? argv[1] : NULL;     /* NULL: ipc:///tmp/bodyd/pose */
  const char* control_endpoint = argc > 2 ? argv[2] : NULL;  /* NULL: ipc:///tmp/bodyd/control */
  bodyd_client* client = bodyd_client_create(pose_endpoint, control_endpoint);
  if (client == NULL) {
    fprintf(stderr, "bodyd_sub_c: %s\n", bodyd_client_error(NULL));
    return 1;
  }
  if (bodyd_client_fetch_skeleton(client, 500) != BODYD_OK) {
    fprintf(stderr, "bodyd_sub_c: no skeleton from the control socket (%s); names follow on the stream\n",
            bodyd_client_error(client));
  }
  bodyd_pose* pose = malloc(sizeof *pose); /* 3.6 KiB: keep it off small stacks */
  for (;;) {
    const int rc = bodyd_client_receive_pose(client, pose, 1000);
    if (rc == BODYD_TIMEOUT) {
      fprintf(stderr, "bodyd_sub_c: waiting for poses...\n");
      continue;
    }
    if (rc == BODYD_ERROR_MALFORMED) {
      fprintf(stderr, "bodyd_sub_c: skipped: %s\n", bodyd_client_error(client));
      continue;
    }
    if (rc != BODYD_OK) {
      fprintf(stderr, "bodyd_sub_c: %s\n", bodyd_client_error(client));
      break;
    }
    const char* root_name = pose->skeleton_id == bodyd_client_skeleton_id(client)
                                ? bodyd_client_skeleton_joint_name(client, pose->root_joint)
                                : NULL;
    printf("seq %llu %s (%.3f, %.3f, %.3f) m heading %.3f rad latency %.3f ms\n", (unsigned long long)pose->seq,
           root_name ? root_name : "root", pose->root_position_m[0], pose->root_position_m[1],
           pose->root_position_m[2], pose->root_heading_rad, (double)(pose->publish_t_ns - pose->t_ns) / 1e6);
  }
  free(pose);
  bodyd_client_destroy(client);
  return 1;
}
