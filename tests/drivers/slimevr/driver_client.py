#!/usr/bin/env python3
"""Stands in for SlimeVR's OpenVR driver (and Monado's feeder) on bodyd's bridge socket.

Written from the protocol's description only (docs/protocol-slimevr-bridge.md and the
upstream schema), with Debian's python3-protobuf and the test's own .proto
(tests/drivers/slimevr/driver_messages.proto, compiled by protoc into PB_DIR at build time).

  driver_client.py PB_DIR play SOCKET POSES OUT [--rate HZ] [--reconnect-after N] [--no-hands]
      Connects (waiting up to 20 s for the socket), sends Version 2, TrackerAdded for the
      headset (role 19) and the controllers (11, 12: LEFT_HAND / RIGHT_HAND, what the driver
      announces from Prop_ControllerRoleHint_Int32; 13, 14 with --controller-roles, what Monado's
      feeder announces) and TrackerStatus OK, then one Position per
      device per frame of POSES (lines "t_ns role x y z qx qy qz qw", role head/left_hand/
      right_hand; a frame starts at each head line) at HZ frames per second (the file
      REPEAT times with --repeat REPEAT). Everything the
      server sends is written to OUT, one JSON object per line. With --reconnect-after N the
      connection is closed after N frames and opened again (a driver that restarts).
  driver_client.py PB_DIR driver SOCKET POSES OUT [--seconds S] [--generic N]
                   [--imu-head T0 T1] [--lost-head T0 T1] [--generic-off T] [--reconnect-at T]
      Behaves as SlimeVR's OpenVR driver (dcc0f56, VRDriver.cpp) does inside SteamVR: Version 2
      once connected, TrackerAdded per device (headset 19, controllers 11 / 12, N generic
      trackers: waist 1, left_foot 2, right_foot 3, chest 4), then on every turn of a 2 ms loop
      a Position per device (the newest pose of POSES at that time, looped; data_source FULL)
      and a Battery per device every 100 ms; TrackerStatus when a device's status changes.
      From T0 to T1 seconds the headset is tracked by rotation only (--imu-head: status
      OCCLUDED, Positions with data_source IMU) or lost (--lost-head: status OCCLUDED, no
      Position). From T seconds on (--generic-off) the generic trackers are switched off: status
      DISCONNECTED, no Position. At T seconds (--reconnect-at) the connection is closed, as by a
      driver that restarts. When the connection fails it connects again after a second. Every message
      from bodyd is written to OUT with its time ("t", seconds since the start) and the run's
      counts at the end ({"kind": "summary", ...}).
  driver_client.py PB_DIR bad SOCKET KIND OUT
      Sends one kind of bad input and writes to OUT whether bodyd closed the connection and
      whether a fresh connection is served afterwards (it gets the TrackerAdded announcements).
"""
import argparse
import json
import os
import select
import socket
import struct
import sys
import time

sys.path.insert(0, sys.argv[1])
import driver_messages_pb2 as pb  # noqa: E402

# role -> (tracker id, SlimeVR role, serial). The driver announces controllers as LEFT_HAND /
# RIGHT_HAND (11 / 12); CONTROLLER_ROLES are Monado's feeder's (13 / 14).
ROLES = {"head": (0, 19, "test-hmd"), "left_hand": (1, 11, "test-left"), "right_hand": (2, 12, "test-right"),
         "waist": (3, 1, "test-waist"), "left_foot": (4, 2, "test-left-foot"), "right_foot": (5, 3, "test-right-foot"),
         "chest": (6, 4, "test-chest")}
CONTROLLER_ROLES = {"left_hand": 13, "right_hand": 14}
GENERIC = ["waist", "left_foot", "right_foot", "chest"]
VERSION = 2  # the driver's PROTOCOL_VERSION (src/bridge/BridgeClient.hpp)


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
        self.t0 = None  # when set, records carry "t" (seconds since t0)

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
        if self.t0 is not None:
            rec["t"] = round(time.monotonic() - self.t0, 4)
        self.count += 1
        if self.out:
            self.out.write(json.dumps(rec) + "\n")


def announce(s, roles, controller_roles=False):
    v = pb.ProtobufMessage()
    v.version.protocol_version = VERSION
    s.sendall(frame(v))
    for role in roles:
        tid, r, serial = ROLES[role]
        if controller_roles:
            r = CONTROLLER_ROLES.get(role, r)
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


def position(role, x, y, z, qx, qy, qz, qw, data_source=3):
    m = pb.ProtobufMessage()
    m.position.tracker_id = ROLES[role][0]
    m.position.x, m.position.y, m.position.z = x, y, z
    m.position.qx, m.position.qy, m.position.qz, m.position.qw = qx, qy, qz, qw
    m.position.data_source = data_source
    return frame(m)


def status(role, st):
    m = pb.ProtobufMessage()
    m.tracker_status.tracker_id = ROLES[role][0]
    m.tracker_status.status = st
    return frame(m)


def battery(role):
    m = pb.ProtobufMessage()
    m.battery.tracker_id = ROLES[role][0]
    m.battery.battery_level = 80.0
    m.battery.is_charging = False
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


def play(a):
    path, poses, out_path = a.socket, a.poses, a.out
    rate, reconnect_after, hands, repeat = a.rate, a.reconnect_after, a.hands, a.repeat
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


def read_timed(path):
    """POSES as [(t_s, {role: vals})], t from the first line, one entry per head line."""
    out = []
    t_first = None
    with open(path) as f:
        for line in f:
            parts = line.split()
            if len(parts) != 9:
                continue
            t = int(parts[0]) * 1e-9
            if t_first is None:
                t_first = t
            if parts[1] == "head" or not out:
                prev = dict(out[-1][1]) if out else {}
                out.append((t - t_first, prev))
            out[-1][1][parts[1]] = [float(v) for v in parts[2:]]
    return out


def driver(a):
    path, poses, out_path = a.socket, a.poses, a.out
    seconds, generic, imu, lost = a.seconds, a.generic, a.imu_head, a.lost_head
    generic_off, reconnect_at = a.generic_off, a.reconnect_at
    roles = ["head", "left_hand", "right_hand"] + GENERIC[:generic]
    timed = read_timed(poses)
    clip_s = timed[-1][0] + 1.0 / 90.0
    counts = {"positions": 0, "batteries": 0, "connects": 0, "loops": 0}
    with open(out_path, "w") as out:
        t0 = time.monotonic()
        s, reader = None, None
        last_status, battery_at = {}, {}
        k = 0
        while True:
            now = time.monotonic() - t0
            if now >= seconds:
                break
            if s is None or reader.closed:
                if s is not None:
                    s.close()
                    out.write(json.dumps({"kind": "closed", "t": round(now, 4)}) + "\n")
                    time.sleep(1.0)  # the driver tries again a second later
                s = connect(path)
                counts["connects"] += 1
                reader = Reader(out)
                reader.t0 = t0
                out.write(json.dumps({"kind": "connected", "t": round(time.monotonic() - t0, 4)}) + "\n")
                announce(s, roles)
                last_status, battery_at = {r: 1 for r in roles}, {}
                continue
            if reconnect_at is not None and now >= reconnect_at:
                reconnect_at = None
                reader.closed = True  # closed above, connected again a second later
                continue
            # The newest pose at this time (the clip looped).
            tc = now % clip_s
            while k + 1 < len(timed) and timed[k + 1][0] <= tc:
                k += 1
            if timed[k][0] > tc:
                k = 0
            pose = timed[k][1]
            data = b""
            for role in roles:
                head = pose.get("head")
                if role in pose:
                    vals = pose[role]
                elif head is not None:  # a generic tracker: somewhere below the head
                    drop = {"waist": 0.75, "left_foot": 1.55, "right_foot": 1.55, "chest": 0.45}[role]
                    side = {"left_foot": 0.1, "right_foot": -0.1}.get(role, 0.0)
                    vals = [head[0] + side, head[1] - drop, head[2]] + head[3:]
                else:
                    continue
                st, ds, send = 1, 3, True
                if role == "head" and imu and imu[0] <= now < imu[1]:
                    st, ds = 4, 1
                if role == "head" and lost and lost[0] <= now < lost[1]:
                    st, send = 4, False
                if role in GENERIC and generic_off is not None and now >= generic_off:
                    st, send = 0, False
                if last_status.get(role) != st:
                    data += status(role, st)
                    last_status[role] = st
                if send:
                    data += position(role, *vals, data_source=ds)
                    counts["positions"] += 1
                if now - battery_at.get(role, -1.0) > 0.1:
                    data += battery(role)
                    battery_at[role] = now
                    counts["batteries"] += 1
            try:
                s.sendall(data)
            except OSError:
                reader.closed = True
                continue
            counts["loops"] += 1
            # The driver's loop sleeps 2 ms after each turn; read what bodyd sends meanwhile.
            end = time.monotonic() + 0.002
            while not reader.closed:
                left = end - time.monotonic()
                reader.poll(s, max(0.0, left))
                if left <= 0:
                    break
        if s is not None:
            s.close()
        counts.update(kind="summary", seconds=round(time.monotonic() - t0, 3))
        out.write(json.dumps(counts) + "\n")


def bad(a):
    path, kind, out_path = a.socket, a.kind, a.out
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
        # Serials and names with terminal escapes, CR and LF (log injection): one with a known
        # role (logged; left shoulder, which bodyd does not use, so this client takes no role of
        # the good driver's session), one with an unknown one (rejected, quoted in the reason).
        for tid, role in ((8, 9), (7, 99)):
            a = pb.ProtobufMessage()
            a.tracker_added.tracker_id = tid
            a.tracker_added.tracker_serial = "weird\x1b[2J\r\n[info] forged line"
            a.tracker_added.tracker_name = "name\x1b]0;owned\x07"
            a.tracker_added.tracker_role = role
            s.sendall(frame(a))
        s.sendall(position("head", 0.0, 1.6, 0.0, 0.0, 0.0, 0.0, 1.0))  # id 0: never announced
    elif kind == "second_headset":
        # Another connection announces a headset 30 m away and moves it for 2 s at 90 Hz: the
        # headset stays the first connection's (bodyd counts role_taken).
        a = pb.ProtobufMessage()
        a.tracker_added.tracker_id = 0
        a.tracker_added.tracker_serial = "intruder-hmd"
        a.tracker_added.tracker_role = 19
        s.sendall(frame(a))
        for _ in range(180):
            s.sendall(position("head", 30.0, 1.6, 30.0, 0.0, 0.0, 0.0, 1.0))
            time.sleep(1.0 / 90.0)
    elif kind == "flood":
        # More frames in a second than any driver sends (bodyd allows 20,000: 8 devices at the
        # driver's 500 Hz with batteries are about 4,100).
        b = pb.ProtobufMessage()
        b.battery.tracker_id = 0
        data = frame(b) * 30000
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


def parse_args(argv):
    """The command line of the module's docstring."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("pb_dir")
    modes = p.add_subparsers(dest="mode", required=True)
    pl = modes.add_parser("play")
    dr = modes.add_parser("driver")
    for m in (pl, dr):
        m.add_argument("socket")
        m.add_argument("poses")
        m.add_argument("out")
    pl.add_argument("--rate", type=float, default=90.0)
    pl.add_argument("--reconnect-after", type=int, default=-1)
    pl.add_argument("--no-hands", dest="hands", action="store_false")
    pl.add_argument("--repeat", type=int, default=1)
    dr.add_argument("--seconds", type=float, default=10.0)
    dr.add_argument("--generic", type=int, default=0)
    dr.add_argument("--imu-head", type=float, nargs=2, metavar=("T0", "T1"))
    dr.add_argument("--lost-head", type=float, nargs=2, metavar=("T0", "T1"))
    dr.add_argument("--generic-off", type=float)
    dr.add_argument("--reconnect-at", type=float)
    bd = modes.add_parser("bad")
    for name in ("socket", "kind", "out"):
        bd.add_argument(name)
    return p.parse_args(argv)


if __name__ == "__main__":
    args = parse_args(sys.argv[1:])
    {"play": play, "driver": driver, "bad": bad}[args.mode](args)
