#!/usr/bin/env python3
"""Stands in for Monado's SolarXR driver on bodyd's SlimeVRRpc and SlimeVRInput sockets.

Written from the protocols' descriptions only (docs/protocol-solarxr.md, the upstream
schemas), with Debian's python3-flatbuffers and python3-protobuf, and the test's own schema
files (solarxr_test.fbs through flatc --python, driver_messages.proto through protoc, both
generated into PB_DIR at build time).

  solarxr_client.py PB_DIR DIR POSES OUT [--rate HZ | --wivrn SECONDS]
  solarxr_client.py PB_DIR bad DIR KIND OUT     (one kind of bad input: see bad())

As Monado does at session start: connects to DIR/SlimeVRRpc, sends one MessageBundle with a
SettingsRequest and a PollDataFeed, and waits at most 4 s for exactly one DataFeedUpdate (it
fails otherwise, as Monado gives up); then sends StartDataFeed, and its feeder plays POSES'
headset and controllers into DIR/SlimeVRInput (SlimeVR's driver protocol) at HZ. Every
DataFeedUpdate and the SettingsResponse are written to OUT as JSON lines.

With --wivrn SECONDS it behaves as Monado's solarxr driver does inside WiVRn (feeder.c,
solarxr_device.c; wivrn_session.cpp's call order): StartDataFeed asks for
minimum_time_since_last 1 ms (Monado's SOLARXR_SYNC_PERIOD_MS default), the feeder connects
only after the first update was consumed (solarxr_device_create_xdevs, then
solarxr_device_set_feeder_devices), announces the headset (19) and controllers (13, 14), and
sends one Position per device for each received bundle with data-feed messages, never before
one (the newest pose of POSES at that time, looped), for SECONDS. Updates carry "t" (seconds
since the start) and the run ends with a {"kind": "summary"} line.
"""
import json
import select
import socket
import struct
import sys
import time

sys.path.insert(0, sys.argv[1])
import flatbuffers  # noqa: E402
from solarxr_protocol import MessageBundle as MB  # noqa: E402
from solarxr_protocol.data_feed import DataFeedConfig as DFC  # noqa: E402
from solarxr_protocol.data_feed import DataFeedMessageHeader as DFH  # noqa: E402
from solarxr_protocol.data_feed import PollDataFeed as PDF  # noqa: E402
from solarxr_protocol.data_feed import StartDataFeed as SDF  # noqa: E402
from solarxr_protocol.data_feed import DataFeedUpdate as DFU  # noqa: E402
from solarxr_protocol.data_feed.DataFeedMessage import DataFeedMessage  # noqa: E402
from solarxr_protocol.data_feed.tracker import TrackerDataMask as TDM  # noqa: E402
from solarxr_protocol.datatypes import TransactionId as TX  # noqa: E402
from solarxr_protocol.rpc import RpcMessageHeader as RMH  # noqa: E402
from solarxr_protocol.rpc import SettingsRequest as SRQ  # noqa: E402
from solarxr_protocol.rpc import SettingsResponse as SRS  # noqa: E402
from solarxr_protocol.rpc.RpcMessage import RpcMessage  # noqa: E402

import driver_client as feeder  # noqa: E402  (the driver protocol side: the same messages)


def mask(b, info, pose):
    TDM.TrackerDataMaskStart(b)
    TDM.TrackerDataMaskAddInfo(b, info)
    TDM.TrackerDataMaskAddRotation(b, pose)
    TDM.TrackerDataMaskAddPosition(b, pose)
    return TDM.TrackerDataMaskEnd(b)


def config(b, info, pose):
    m = mask(b, info, pose)
    DFC.DataFeedConfigStart(b)
    DFC.DataFeedConfigAddMinimumTimeSinceLast(b, 1)
    DFC.DataFeedConfigAddSyntheticTrackersMask(b, m)
    DFC.DataFeedConfigAddBoneMask(b, True)
    return DFC.DataFeedConfigEnd(b)


def bundle(feed_type, feed_builder, with_settings):
    b = flatbuffers.Builder(256)
    msg = feed_builder(b)
    DFH.DataFeedMessageHeaderStart(b)
    DFH.DataFeedMessageHeaderAddMessageType(b, feed_type)
    DFH.DataFeedMessageHeaderAddMessage(b, msg)
    header = DFH.DataFeedMessageHeaderEnd(b)
    rpc = None
    if with_settings:
        SRQ.SettingsRequestStart(b)
        req = SRQ.SettingsRequestEnd(b)
        RMH.RpcMessageHeaderStart(b)
        RMH.RpcMessageHeaderAddTxId(b, TX.CreateTransactionId(b, 41))
        RMH.RpcMessageHeaderAddMessageType(b, RpcMessage.SettingsRequest)
        RMH.RpcMessageHeaderAddMessage(b, req)
        rh = RMH.RpcMessageHeaderEnd(b)
        MB.MessageBundleStartRpcMsgsVector(b, 1)
        b.PrependUOffsetTRelative(rh)
        rpc = b.EndVector()
    MB.MessageBundleStartDataFeedMsgsVector(b, 1)
    b.PrependUOffsetTRelative(header)
    feeds = b.EndVector()
    MB.MessageBundleStart(b)
    MB.MessageBundleAddDataFeedMsgs(b, feeds)
    if rpc is not None:
        MB.MessageBundleAddRpcMsgs(b, rpc)
    b.Finish(MB.MessageBundleEnd(b))
    data = bytes(b.Output())
    return struct.pack("<I", len(data) + 4) + data


def poll_msg(b):
    c = config(b, True, True)
    PDF.PollDataFeedStart(b)
    PDF.PollDataFeedAddConfig(b, c)
    return PDF.PollDataFeedEnd(b)


def start_msg(b):
    c = config(b, False, True)
    SDF.StartDataFeedStartDataFeedsVector(b, 1)
    b.PrependUOffsetTRelative(c)
    v = b.EndVector()
    SDF.StartDataFeedStart(b)
    SDF.StartDataFeedAddDataFeeds(b, v)
    return SDF.StartDataFeedEnd(b)


class Rpc:
    def __init__(self, s, out):
        self.s, self.out, self.buf, self.updates = s, out, b"", 0
        self.settings = None
        self.bundles_with_feed = 0  # bundles holding data-feed messages (the feeder's trigger)
        self.t0 = time.monotonic()

    def poll(self, wait_s):
        r, _, _ = select.select([self.s], [], [], wait_s)
        if not r:
            return
        data = self.s.recv(1 << 20)
        if not data:
            raise SystemExit("bodyd closed SlimeVRRpc")
        self.buf += data
        while len(self.buf) >= 4:
            (n,) = struct.unpack("<I", self.buf[:4])
            if n < 4:
                raise SystemExit("bad frame length %d" % n)
            if len(self.buf) < n:
                break
            self.handle(self.buf[4:n])
            self.buf = self.buf[n:]

    def handle(self, payload):
        m = MB.MessageBundle.GetRootAs(bytearray(payload), 0)
        for i in range(m.RpcMsgsLength()):
            h = m.RpcMsgs(i)
            if h.MessageType() == RpcMessage.SettingsResponse:
                r = SRS.SettingsResponse()
                r.Init(h.Message().Bytes, h.Message().Pos)
                t = r.SteamVrTrackers()
                self.settings = {k: getattr(t, k)() for k in ("Waist", "Chest", "LeftFoot", "RightFoot", "LeftKnee",
                                                              "RightKnee", "LeftElbow", "RightElbow", "LeftHand",
                                                              "RightHand")}
                self.out.write(json.dumps({"kind": "settings", "tx": h.TxId().Id(), "steamvr": self.settings}) + "\n")
        if m.DataFeedMsgsLength() > 0:
            self.bundles_with_feed += 1
        for i in range(m.DataFeedMsgsLength()):
            h = m.DataFeedMsgs(i)
            if h.MessageType() != DataFeedMessage.DataFeedUpdate:
                continue
            u = DFU.DataFeedUpdate()
            u.Init(h.Message().Bytes, h.Message().Pos)
            rec = {"kind": "update", "t": round(time.monotonic() - self.t0, 4), "trackers": [], "bones": []}
            for k in range(u.SyntheticTrackersLength()):
                t = u.SyntheticTrackers(k)
                tr = {"num": t.TrackerId().TrackerNum(), "status": t.Status()}
                if t.Info() is not None:
                    tr["body_part"] = t.Info().BodyPart()
                    tr["name"] = (t.Info().DisplayName() or b"").decode()
                if t.Position() is not None:
                    p, q = t.Position(), t.Rotation()
                    tr["p"] = [p.X(), p.Y(), p.Z()]
                    tr["q"] = [q.X(), q.Y(), q.Z(), q.W()]
                rec["trackers"].append(tr)
            for k in range(u.BonesLength()):
                bo = u.Bones(k)
                q, h3 = bo.RotationG(), bo.HeadPositionG()
                rec["bones"].append({"part": bo.BodyPart(), "q": [q.X(), q.Y(), q.Z(), q.W()], "len": bo.BoneLength(),
                                     "head": [h3.X(), h3.Y(), h3.Z()]})
            self.updates += 1
            self.out.write(json.dumps(rec) + "\n")


def main():
    d, poses, out_path = sys.argv[2], sys.argv[3], sys.argv[4]
    rate = 90.0
    if len(sys.argv) > 6 and sys.argv[5] == "--rate":
        rate = float(sys.argv[6])
    if len(sys.argv) > 6 and sys.argv[5] == "--wivrn":
        return wivrn(d, poses, out_path, float(sys.argv[6]))
    with open(out_path, "w") as out:
        s = feeder.connect(d + "/SlimeVRRpc")
        rpc = Rpc(s, out)
        t0 = time.monotonic()
        s.sendall(bundle(DataFeedMessage.PollDataFeed, poll_msg, True))
        while rpc.updates == 0 and time.monotonic() - t0 < 4.0:
            rpc.poll(0.05)
        if rpc.updates != 1:
            raise SystemExit("no DataFeedUpdate within the 4 s Monado waits")
        out.write(json.dumps({"kind": "first_update_s", "s": time.monotonic() - t0}) + "\n")
        deadline = time.monotonic() + 2.0
        while rpc.settings is None and time.monotonic() < deadline:
            rpc.poll(0.05)
        s.sendall(bundle(DataFeedMessage.StartDataFeed, start_msg, False))
        f = feeder.connect(d + "/SlimeVRInput")
        feeder.announce(f, ["head", "left_hand", "right_hand"], controller_roles=True)
        period = 1.0 / rate
        next_t = time.monotonic()
        for fr in feeder.read_frames(poses):
            f.sendall(b"".join(feeder.position(role, *vals) for role, vals in fr))
            next_t += period
            while True:
                left = next_t - time.monotonic()
                rpc.poll(max(0.0, left))
                if left <= 0:
                    break
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            rpc.poll(0.05)
        f.close()
        s.close()


def wivrn(d, poses, out_path, seconds):
    roles = ["head", "left_hand", "right_hand"]
    timed = feeder.read_timed(poses)
    clip_s = timed[-1][0] + 1.0 / 90.0
    with open(out_path, "w") as out:
        s = feeder.connect(d + "/SlimeVRRpc")
        rpc = Rpc(s, out)
        t0 = rpc.t0
        s.sendall(bundle(DataFeedMessage.PollDataFeed, poll_msg, True))
        while rpc.updates == 0 and time.monotonic() - t0 < 4.0:
            rpc.poll(0.05)
        if rpc.updates != 1:
            raise SystemExit("no DataFeedUpdate within the 4 s Monado waits")
        # The answer to the poll is consumed here (solarxr_device_create_xdevs); StartDataFeed
        # follows at once, and the feeder's devices come later (solarxr_device_set_feeder_devices).
        s.sendall(bundle(DataFeedMessage.StartDataFeed, start_msg, False))
        while rpc.settings is None and time.monotonic() - t0 < 4.0:
            rpc.poll(0.05)
        time.sleep(0.2)
        f = feeder.connect(d + "/SlimeVRInput")
        feeder.announce(f, roles, controller_roles=True)
        devices_s = time.monotonic() - t0
        out.write(json.dumps({"kind": "feeder_devices", "t": round(devices_s, 4)}) + "\n")
        seen = rpc.bundles_with_feed
        samples = 0
        k = 0
        while time.monotonic() - t0 < seconds:
            rpc.poll(0.05)
            if rpc.bundles_with_feed == seen:
                continue
            seen = rpc.bundles_with_feed  # one sample per device per bundle received
            tc = (time.monotonic() - t0) % clip_s
            while k + 1 < len(timed) and timed[k + 1][0] <= tc:
                k += 1
            if timed[k][0] > tc:
                k = 0
            pose = timed[k][1]
            f.sendall(b"".join(feeder.position(r, *pose[r]) for r in roles if r in pose))
            samples += 1
        out.write(json.dumps({"kind": "summary", "updates": rpc.updates, "feeder_rounds": samples,
                              "feeder_devices_s": round(devices_s, 4)}) + "\n")
        f.close()
        s.close()


def bad():
    """solarxr_client.py PB_DIR bad DIR KIND OUT: one kind of bad input on SlimeVRRpc, then
    whether bodyd closed that connection and whether a fresh one still gets its poll answered."""
    d, kind, out_path = sys.argv[3], sys.argv[4], sys.argv[5]
    s = feeder.connect(d + "/SlimeVRRpc")
    if kind == "too_long":
        s.sendall(struct.pack("<I", 100000) + b"\0" * 64)
    elif kind == "too_short":
        s.sendall(struct.pack("<I", 3) + b"\0" * 8)
    elif kind == "malformed":
        s.sendall(struct.pack("<I", 4 + 12) + b"\x0c\x00\x00\x00\xff\xff\xff\x7f\x01\x02\x03\x04")
    elif kind == "flood":
        one = bundle(DataFeedMessage.StartDataFeed, start_msg, False)
        try:
            s.sendall(one * 3000)
        except OSError:
            pass
    else:
        raise SystemExit("unknown bad kind " + kind)
    closed = False
    end = time.monotonic() + 2.0
    while time.monotonic() < end and not closed:
        r, _, _ = select.select([s], [], [], 0.05)
        if r:
            try:
                closed = not s.recv(1 << 20)
            except OSError:
                closed = True
    s.close()
    s2 = feeder.connect(d + "/SlimeVRRpc", 5.0)
    rpc = Rpc(s2, open(out_path + ".updates", "w"))
    s2.sendall(bundle(DataFeedMessage.PollDataFeed, poll_msg, False))
    t0 = time.monotonic()
    while rpc.updates == 0 and time.monotonic() - t0 < 4.0:
        rpc.poll(0.05)
    s2.close()
    with open(out_path, "w") as out:
        out.write(json.dumps({"kind": kind, "closed": closed, "served_after": rpc.updates > 0}) + "\n")


if __name__ == "__main__":
    if sys.argv[2] == "bad":
        bad()
    else:
        main()
