#!/usr/bin/env python3
"""Example subscriber for bodyd's pose stream, written from docs/protocol.md alone.

Needs only python3-zmq and the standard library (struct for the binary messages).

    bodyd_sub.py [--endpoint ipc:///tmp/bodyd/pose] [--count N] [--json] [--timeout-s S]

Prints one line per pose: a summary by default, or with --json one JSON object with every
decoded field (joint positions keyed by joint name once the skeleton is known).
Exit status: 0 done, 1 error, 2 no pose within --timeout-s.
"""

import argparse
import json
import math
import struct
import sys
import time

import zmq

# --- Protocol version 1 (docs/protocol.md) ---------------------------------------------------

POSE_MAGIC = b"BDPO"
SKELETON_MAGIC = b"BDSK"
VERSION = 1
MAX_JOINTS = 128
MAX_NAME_BYTES = 63

POSE_HEADER = struct.Struct("<4sHHQqqIIHBx3ffI")  # 64 bytes
POSE_JOINT = struct.Struct("<7f")                 # position xyz, rotation xyzw: 28 bytes
SKELETON_HEADER = struct.Struct("<4sHHII")        # 16 bytes
SKELETON_JOINT = struct.Struct("<hH3f")           # parent, name_length, offset xyz: 16 bytes

FLAG_NAMES = ["head_valid", "left_hand_valid", "right_hand_valid", "height_calibrated", "offsets_calibrated"]


class DecodeError(ValueError):
    pass


def fnv1a32(data):
    h = 0x811C9DC5
    for b in data:
        h = ((h ^ b) * 0x01000193) & 0xFFFFFFFF
    return h or 1


def decode_pose(msg):
    if len(msg) < POSE_HEADER.size:
        raise DecodeError(f"pose: {len(msg)} bytes, shorter than the {POSE_HEADER.size}-byte header")
    (magic, version, n, seq, t_ns, publish_t_ns, flags, skeleton_id, root_joint, foot_contact,
     rx, ry, rz, heading, _reserved) = POSE_HEADER.unpack_from(msg, 0)
    if magic != POSE_MAGIC:
        raise DecodeError(f"pose: wrong magic {magic!r}")
    if version != VERSION:
        raise DecodeError(f"pose: unsupported version {version}")
    if n > MAX_JOINTS:
        raise DecodeError(f"pose: joint_count {n} exceeds {MAX_JOINTS}")
    if len(msg) != POSE_HEADER.size + POSE_JOINT.size * n:
        raise DecodeError(f"pose: {len(msg)} bytes, joint_count {n} needs {POSE_HEADER.size + POSE_JOINT.size * n}")
    if root_joint != 0xFFFF and root_joint >= n:
        raise DecodeError(f"pose: root_joint {root_joint} out of range")
    positions, rotations = [], []
    for i in range(n):
        px, py, pz, qx, qy, qz, qw = POSE_JOINT.unpack_from(msg, POSE_HEADER.size + POSE_JOINT.size * i)
        if not all(math.isfinite(v) for v in (px, py, pz, qx, qy, qz, qw)):
            raise DecodeError(f"pose: joint {i} is not finite")
        positions.append([px, py, pz])
        rotations.append([qx, qy, qz, qw])
    return {
        "seq": seq, "t_ns": t_ns, "publish_t_ns": publish_t_ns, "flags": flags,
        "skeleton_id": skeleton_id,
        "root_joint": None if root_joint == 0xFFFF else root_joint,
        "foot_contact": [bool(foot_contact & 1), bool(foot_contact & 2)],
        "root_position_m": [rx, ry, rz], "root_heading_rad": heading,
        "positions_m": positions, "rotations_xyzw": rotations,
    }


def decode_skeleton(msg):
    if len(msg) < SKELETON_HEADER.size:
        raise DecodeError(f"skeleton: {len(msg)} bytes, shorter than the header")
    magic, version, n, skeleton_id, _reserved = SKELETON_HEADER.unpack_from(msg, 0)
    if magic != SKELETON_MAGIC:
        raise DecodeError(f"skeleton: wrong magic {magic!r}")
    if version not in (1, 2):  # version 2 adds a rest rotation to each joint entry
        raise DecodeError(f"skeleton: unsupported version {version}")
    if not 1 <= n <= MAX_JOINTS:
        raise DecodeError(f"skeleton: joint_count {n} out of range 1..{MAX_JOINTS}")
    pos = SKELETON_HEADER.size
    names, parents, offsets, rests = [], [], [], []
    for i in range(n):
        if pos + SKELETON_JOINT.size > len(msg):
            raise DecodeError(f"skeleton: truncated in joint {i}")
        parent, length, ox, oy, oz = SKELETON_JOINT.unpack_from(msg, pos)
        pos += SKELETON_JOINT.size
        if version == 2:
            if pos + 16 > len(msg):
                raise DecodeError(f"skeleton: truncated in joint {i}")
            rests.append(list(struct.unpack_from("<4f", msg, pos)))
            pos += 16
        if not 1 <= length <= MAX_NAME_BYTES or pos + length > len(msg):
            raise DecodeError(f"skeleton: joint {i} name_length {length} invalid")
        name = bytes(msg[pos:pos + length]).decode("utf-8")  # raises on invalid UTF-8
        pos += length
        if (i == 0 and parent != -1) or (i > 0 and not 0 <= parent < i):
            raise DecodeError(f"skeleton: joint {i} parent {parent} out of range")
        names.append(name)
        parents.append(parent)
        offsets.append([ox, oy, oz])
    if pos != len(msg):
        raise DecodeError(f"skeleton: {len(msg) - pos} trailing bytes")
    if fnv1a32(bytes(msg[SKELETON_HEADER.size:])) != skeleton_id:
        raise DecodeError("skeleton: skeleton_id does not match the joint table's hash")
    skeleton = {"skeleton_id": skeleton_id, "names": names, "parents": parents, "offsets_m": offsets}
    if version == 2:
        skeleton["rest_rotations_xyzw"] = rests
    return skeleton


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--endpoint", default="ipc:///tmp/bodyd/pose")
    parser.add_argument("--count", type=int, default=0, help="exit after N poses (0: run until Ctrl-C)")
    parser.add_argument("--json", action="store_true", help="print each pose as one JSON object")
    parser.add_argument("--timeout-s", type=float, default=0.0, help="exit 2 if no pose arrives for this long")
    args = parser.parse_args()

    sub = zmq.Context.instance().socket(zmq.SUB)
    sub.setsockopt(zmq.LINGER, 0)
    sub.setsockopt(zmq.SUBSCRIBE, b"pose")
    sub.setsockopt(zmq.SUBSCRIBE, b"skeleton")
    sub.connect(args.endpoint)
    poller = zmq.Poller()
    poller.register(sub, zmq.POLLIN)

    skeletons = {}
    received = dropped = 0
    last_seq = None
    last_pose_time = time.monotonic()
    try:
        while args.count == 0 or received < args.count:
            if not poller.poll(100):
                if args.timeout_s > 0 and time.monotonic() - last_pose_time > args.timeout_s:
                    print(f"bodyd_sub.py: no pose from {args.endpoint} for {args.timeout_s} s", file=sys.stderr)
                    return 2
                continue
            frames = sub.recv_multipart(copy=False)
            if len(frames) != 2:
                continue  # not a version-1 message
            topic, msg = bytes(frames[0].buffer), frames[1].buffer
            try:
                if topic == b"skeleton":
                    sk = decode_skeleton(msg)
                    skeletons[sk["skeleton_id"]] = sk
                    continue
                if topic != b"pose":
                    continue  # a later protocol's topic
                pose = decode_pose(msg)
            except (DecodeError, UnicodeDecodeError) as e:
                print(f"bodyd_sub.py: skipped a message: {e}", file=sys.stderr)
                continue
            received += 1
            last_pose_time = time.monotonic()
            if last_seq is not None and pose["seq"] > last_seq + 1:
                dropped += pose["seq"] - last_seq - 1
            last_seq = pose["seq"]
            sk = skeletons.get(pose["skeleton_id"])
            if sk is not None and len(sk["names"]) == len(pose["positions_m"]):
                pose["joints"] = dict(zip(sk["names"], pose["positions_m"]))
            if args.json:
                print(json.dumps(pose), flush=True)
            else:
                flags = ",".join(name for bit, name in enumerate(FLAG_NAMES) if pose["flags"] >> bit & 1)
                root = pose["root_position_m"]
                print(f"seq {pose['seq']} t_ns {pose['t_ns']} joints {len(pose['positions_m'])} "
                      f"root ({root[0]:.3f}, {root[1]:.3f}, {root[2]:.3f}) heading {pose['root_heading_rad']:.3f} "
                      f"flags [{flags}] dropped {dropped}", flush=True)
    except KeyboardInterrupt:
        pass
    print(f"bodyd_sub.py: {received} poses, {dropped} dropped", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
