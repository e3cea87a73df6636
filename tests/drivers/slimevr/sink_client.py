#!/usr/bin/env python3
"""A client that connects to a bodyd bridge and reads everything, for the latency benchmark
(docs/outputs.md, "Benchmark"): the steamvr output then has a driver to write to, the monado
output a client that started a data feed.

  sink_client.py PB_DIR steamvr SOCKET     as SlimeVR's driver, announcing nothing
  sink_client.py PB_DIR monado DIR         as Monado: StartDataFeed on DIR/SlimeVRRpc
Connects again whenever the server goes (each benchmark run is a new one); runs until killed
and prints the bytes it read (SIGTERM/SIGINT).
"""
import signal
import sys

sys.path.insert(0, sys.argv[1])
import driver_client as feeder  # noqa: E402

read = 0


def stop(*_):
    print("read %d bytes" % read, flush=True)
    sys.exit(0)


signal.signal(signal.SIGTERM, stop)
signal.signal(signal.SIGINT, stop)
connections = 0
while True:  # each benchmark run is a new server: connect again
    if sys.argv[2] == "steamvr":
        s = feeder.connect(sys.argv[3], 3600.0)
    else:
        import solarxr_client as sx
        s = feeder.connect(sys.argv[3] + "/SlimeVRRpc", 3600.0)
        s.sendall(sx.bundle(sx.DataFeedMessage.StartDataFeed, sx.start_msg, False))
    connections += 1
    print("connection %d" % connections, flush=True)
    while True:
        try:
            data = s.recv(1 << 20)
        except OSError:
            data = b""
        if not data:
            break
        read += len(data)
    s.close()
