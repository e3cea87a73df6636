#!/usr/bin/env python3
"""Stands in for SlimeVR's OpenVR driver (and Monado's feeder) on bodyd's bridge socket.

Written from the protocol's description only (docs/protocol-slimevr-bridge.md and the
upstream schema), with Debian's python3-protobuf and the test's own .proto
(tests/drivers/slimevr/driver_messages.proto, compiled by protoc into PB_DIR at build time).

  driver_client.py PB_DIR play SOCKET POSES OUT [--rate HZ] [--reconnect-after N] [--no-hands]
      Connects (waiting up to 20 s for the socket), sends Version, TrackerAdded for the
      headset (role 19) and the controllers (13, 14) and TrackerStatus OK, then one Position per
      device per frame of POSES (lines "t_ns role x y z qx qy qz qw", role head/left_hand/
      right_hand; a frame starts at each head line) at HZ frames per second (the file
      REPEAT times with --repeat REPEAT). Everything the
      server sends is written to OUT, one JSON object per line. With --reconnect-after N the
      connection is closed after N frames and opened again (a driver that restarts).
  driver_client.py PB_DIR bad SOCKET KIND OUT
      Sends one kind of bad input and writes to OUT whether bodyd closed the connection and
      whether a fresh connection is served afterwards (it gets the TrackerAdded announcements).
"""
import json
import os
import select
import socket
import struct
import sys
import time

sys.path.insert(0, sys.argv[1])
import driver_messages_pb2 as pb  # noqa: E402

ROLES = {"head": (0, 19, "test-hmd"), "left_hand": (1, 13, "test-left"), "right_hand": (2, 14, "test-right")}


def frame(msg):
    body = msg.SerializeToString()
    return struct.pack("<I", len(body) + 4) + body


def connect(path, timeout_s=20.0):
    deadline = time.monotonic() + timeout_s
    while True:
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            s.connect(path)
            return s
        except OSError:
            s.close()
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)


class Reader:
    """Splits the server's byte stream into frames and records each message."""

    def __init__(self, out):
        self.buf = b""
        self.out = out
        self.closed = False
        self.count = 0

    def poll(self, s, wait_s=0.0):
        while True:
            r, _, _ = select.select([s], [], [], wait_s)
            if not r:
                return
            wait_s = 0.0
            data = s.recv(65536)
            if not data:
                self.closed = True
                return
            self.buf += data
            while len(self.buf) >= 4:
                (n,) = struct.unpack("<I", self.buf[:4])
                if n < 4 or n > 1024:
                    raise SystemExit("bad frame length %d from the server" % n)
                if len(self.buf) < n:
                    break
                m = pb.ProtobufMessage()
                m.ParseFromString(self.buf[4:n])
                self.buf = self.buf[n:]
                self.record(m)

    def record(self, m):
        kind = m.WhichOneof("message")
        rec = {"kind": kind}
        if kind == "position":
            p = m.position
            rec.update(id=p.tracker_id, p=[p.x, p.y, p.z], q=[p.qx, p.qy, p.qz, p.qw], has_p=p.HasField("x"))
        elif kind == "tracker_added":
            a = m.tracker_added
            rec.update(id=a.tracker_id, serial=a.tracker_serial, name=a.tracker_name, role=a.tracker_role)
        elif kind == "tracker_status":
            rec.update(id=m.tracker_status.tracker_id, status=m.tracker_status.status)
        elif kind == "version":
            rec.update(version=m.version.protocol_version)
        self.count += 1
        if self.out:
            self.out.write(json.dumps(rec) + "\n")


def announce(s, roles):
    v = pb.ProtobufMessage()
    v.version.protocol_version = 5
    s.sendall(frame(v))
    for role in roles:
        tid, r, serial = ROLES[role]
        a = pb.ProtobufMessage()
        a.tracker_added.tracker_id = tid
        a.tracker_added.tracker_serial = serial
        a.tracker_added.tracker_name = serial
        a.tracker_added.tracker_role = r
        a.tracker_added.manufacturer = "test"
        st = pb.ProtobufMessage()
        st.tracker_status.tracker_id = tid
        st.tracker_status.status = 1
        s.sendall(frame(a) + frame(st))


def position(role, x, y, z, qx, qy, qz, qw):
    m = pb.ProtobufMessage()
    m.position.tracker_id = ROLES[role][0]
    m.position.x, m.position.y, m.position.z = x, y, z
    m.position.qx, m.position.qy, m.position.qz, m.position.qw = qx, qy, qz, qw
    m.position.data_source = 3
    return frame(m)


def read_frames(path):
    frames = []
    with open(path) as f:
        for line in f:
            parts = line.split()
            if len(parts) != 9:
                continue
            role = parts[1]
            vals = [float(v) for v in parts[2:]]
            if role == "head" or not frames:
                frames.append([])
            frames[-1].append((role, vals))
    return frames


def play(args):
    path, poses, out_path = args[0], args[1], args[2]
    rate = 90.0
    reconnect_after = -1
    hands = True
    repeat = 1
    i = 3
    while i < len(args):
        if args[i] == "--rate":
            rate = float(args[i + 1]); i += 2
        elif args[i] == "--reconnect-after":
            reconnect_after = int(args[i + 1]); i += 2
        elif args[i] == "--no-hands":
            hands = False; i += 1
        elif args[i] == "--repeat":
            repeat = int(args[i + 1]); i += 2
        else:
            raise SystemExit("unknown option " + args[i])
    roles = ["head", "left_hand", "right_hand"] if hands else ["head"]
    frames = read_frames(poses) * repeat
    with open(out_path, "w") as out:
        reader = Reader(out)
        s = connect(path)
        out.write(json.dumps({"kind": "connected"}) + "\n")
        announce(s, roles)
        period = 1.0 / rate
        next_t = time.monotonic()
        for n, fr in enumerate(frames):
            if n == reconnect_after:
                reader.poll(s, 0.3)
                s.close()
                reader = Reader(out)
                time.sleep(0.3)
                s = connect(path)
                out.write(json.dumps({"kind": "connected"}) + "\n")
                announce(s, roles)
            data = b"".join(position(role, *vals) for role, vals in fr if role in roles)
            s.sendall(data)
            next_t += period
            while True:  # the frame's period, reading what bodyd sends meanwhile
                left = next_t - time.monotonic()
                reader.poll(s, max(0.0, left))
                if left <= 0 or reader.closed:
                    break
            if reader.closed:
                raise SystemExit("bodyd closed the connection after frame %d" % n)
        end = time.monotonic() + 1.0
        while time.monotonic() < end and not reader.closed:
            reader.poll(s, 0.05)
        s.close()


def bad(args):
    path, kind, out_path = args[0], args[1], args[2]
    s = connect(path)
    result = {"kind": kind}
    if kind == "too_long":
        s.sendall(struct.pack("<I", 5000) + b"\0" * 100)
    elif kind == "too_short":
        s.sendall(struct.pack("<I", 2) + b"\0" * 8)
    elif kind == "malformed":
        s.sendall(struct.pack("<I", 4 + 5) + b"\x0a\xff\xff\xff\xff")  # a field longer than the frame
    elif kind == "nan_pose":
        announce(s, ["head"])
        s.sendall(position("head", float("nan"), 1.6, 0.0, 0.0, 0.0, 0.0, 1.0))
        s.sendall(position("head", 0.0, 1e9, 0.0, 0.0, 0.0, 0.0, 1.0))
        s.sendall(position("head", 0.0, 1.6, 0.0, 0.0, 0.0, 0.0, 5.0))
    elif kind == "unknown_role":
        a = pb.ProtobufMessage()
        a.tracker_added.tracker_id = 7
        a.tracker_added.tracker_serial = "weird"
        a.tracker_added.tracker_role = 99
        s.sendall(frame(a))
        s.sendall(position("head", 0.0, 1.6, 0.0, 0.0, 0.0, 0.0, 1.0))  # id 0: never announced
    elif kind == "flood":
        v = pb.ProtobufMessage()
        v.version.protocol_version = 5
        data = frame(v) * 3000
        try:
            s.sendall(data)
        except OSError:
            pass
    elif kind == "never_reads":
        # Connect and read nothing; the test makes bodyd send to it. Keep it open a while.
        time.sleep(float(os.environ.get("NEVER_READS_S", "4")))
    else:
        raise SystemExit("unknown bad kind " + kind)
    # Did bodyd close it? (EOF within 2 s; the announcements are read and discarded.)
    reader = Reader(None)
    end = time.monotonic() + 2.0
    try:
        while time.monotonic() < end and not reader.closed:
            reader.poll(s, 0.05)
    except (ConnectionResetError, SystemExit):
        reader.closed = True
    result["closed"] = reader.closed
    s.close()
    # A fresh connection is still served.
    s2 = connect(path, 5.0)
    r2 = Reader(None)
    end = time.monotonic() + 2.0
    while time.monotonic() < end and r2.count == 0 and not r2.closed:
        r2.poll(s2, 0.05)
    result["served_after"] = r2.count > 0
    s2.close()
    with open(out_path, "w") as out:
        out.write(json.dumps(result) + "\n")


if __name__ == "__main__":
    mode = sys.argv[2]
    if mode == "play":
        play(sys.argv[3:])
    elif mode == "bad":
        bad(sys.argv[3:])
    else:
        raise SystemExit("usage: driver_client.py PB_DIR play|bad ...")
