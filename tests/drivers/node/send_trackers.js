// Plays a tracker log (docs/tracker-log.md) into a bodyd network input, as an app would send it,
// with osc.js (the npm `osc` package) for OSC: an OSC implementation bodyd's authors did not write.
//
//   node send_trackers.js MODE HOST PORT LOG [INTERVAL_MS]
//
// MODE vmc:    one bundle per time step: /VMC/Ext/Hmd/Pos "HMD-1" (head), /VMC/Ext/Con/Pos
//              "CON-LEFT" / "CON-RIGHT" (hands), serial px py pz qx qy qz qw in Unity's axes.
// MODE vrchat: one bundle per time step: /tracking/vrsystem/{head,leftwrist,rightwrist}/pose,
//              px py pz and Unity Euler angles in degrees (Quaternion.eulerAngles: Z, then X, then Y).
// MODE udp:    every line of the log, one per datagram (Node's dgram).
// bodyd -> Unity: position (x, y, -z), quaternion (-qx, -qy, qz, qw) (docs/vr-apps.md).
// Invalid samples are skipped by vmc and vrchat (those protocols cannot say "lost").
// Prints "sent N" (messages or datagrams) and exits 0.
'use strict';
const fs = require('fs');
const dgram = require('dgram');

const [mode, host, portText, logPath, intervalText] = process.argv.slice(2);
const port = Number(portText);
const intervalMs = intervalText === undefined ? 1 : Number(intervalText);
const lines = fs.readFileSync(logPath, 'utf8').split('\n').filter((l) => l.length > 0);

function parseSamples() {
  const samples = [];
  for (const line of lines) {
    if (line.startsWith('#') || line.startsWith('t_ns,')) continue;
    const f = line.split(',');
    if (f[2] !== '1') continue;
    const v = f.slice(3).map(Number);
    samples.push({t: f[0], role: f[1], p: v.slice(0, 3), q: v.slice(3, 7)});
  }
  return samples;
}

function toUnity(s) {
  return {p: [s.p[0], s.p[1], -s.p[2]], q: [-s.q[0], -s.q[1], s.q[2], s.q[3]]};
}

// Unity's Quaternion.eulerAngles for q = Ry(y) Rx(x) Rz(z), in degrees within [0, 360).
function unityEulerDeg(q) {
  const [x, y, z, w] = q;
  // Entries m<row><column> of the rotation matrix (column vectors). With R = Ry(b) Rx(a) Rz(c):
  // m12 = -sin a, (m02, m22) = cos a (sin b, cos b), (m10, m11) = cos a (sin c, cos c).
  const m12 = 2 * (y * z - w * x);
  const m02 = 2 * (x * z + w * y), m22 = 1 - 2 * (x * x + y * y);
  const m10 = 2 * (x * y + w * z), m11 = 1 - 2 * (x * x + z * z);
  const m00 = 1 - 2 * (y * y + z * z), m20 = 2 * (x * z - w * y);
  const sx = Math.max(-1, Math.min(1, -m12));
  const ax = Math.asin(sx);
  let ay, az;
  if (Math.abs(sx) < 0.9999999) {
    ay = Math.atan2(m02, m22);
    az = Math.atan2(m10, m11);
  } else {  // gimbal lock: z = 0
    ay = Math.atan2(-m20, m00);
    az = 0;
  }
  const deg = (r) => {
    let d = (r * 180) / Math.PI;
    if (d < 0) d += 360;
    return d;
  };
  return [deg(ax), deg(ay), deg(az)];
}

function groupByTime(samples) {
  const groups = [];
  for (const s of samples) {
    if (groups.length === 0 || groups[groups.length - 1][0].t !== s.t) groups.push([s]);
    else groups[groups.length - 1].push(s);
  }
  return groups;
}

const f = (value) => ({type: 'f', value});

function oscPacket(group) {
  const packets = [];
  for (const s of group) {
    const u = toUnity(s);
    if (mode === 'vmc') {
      const address = s.role === 'head' ? '/VMC/Ext/Hmd/Pos' : '/VMC/Ext/Con/Pos';
      const serial = s.role === 'head' ? 'HMD-1' : s.role === 'left_hand' ? 'CON-LEFT' : 'CON-RIGHT';
      packets.push({address, args: [{type: 's', value: serial}, ...u.p.map(f), ...u.q.map(f)]});
    } else {
      const part = s.role === 'head' ? 'head' : s.role === 'left_hand' ? 'leftwrist' : 'rightwrist';
      packets.push({address: `/tracking/vrsystem/${part}/pose`, args: [...u.p.map(f), ...unityEulerDeg(u.q).map(f)]});
    }
  }
  return {timeTag: {raw: [0, 1]}, packets};
}

function run() {
  let sent = 0;
  if (mode === 'udp') {
    const socket = dgram.createSocket('udp4');
    let i = 0;
    const next = () => {
      if (i >= lines.length) {
        socket.close();
        console.log(`sent ${sent}`);
        return;
      }
      socket.send(Buffer.from(lines[i++] + '\n'), port, host, () => {
        sent++;
        setTimeout(next, intervalMs);
      });
    };
    next();
    return;
  }
  const osc = require('osc');
  const groups = groupByTime(parseSamples());
  const udp = new osc.UDPPort({localAddress: '127.0.0.1', localPort: 0, remoteAddress: host, remotePort: port,
                               metadata: true});
  udp.on('error', (e) => {
    console.error(`osc error: ${e.message}`);
    process.exit(1);
  });
  udp.on('ready', () => {
    let i = 0;
    const next = () => {
      if (i >= groups.length) {
        console.log(`sent ${sent}`);
        udp.close();
        return;
      }
      const packet = oscPacket(groups[i++]);
      udp.send(packet);
      sent += packet.packets.length;
      setTimeout(next, intervalMs);
    };
    next();
  });
  udp.open();
}

if (!['vmc', 'vrchat', 'udp'].includes(mode) || !(port > 0) || !logPath) {
  console.error('usage: node send_trackers.js vmc|vrchat|udp HOST PORT LOG [INTERVAL_MS]');
  process.exit(2);
}
run();
