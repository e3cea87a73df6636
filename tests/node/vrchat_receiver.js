// Stands in for VRChat's OSC tracker input (docs/outputs.md "vrchat"), with osc.js (the npm
// `osc` package), an OSC implementation bodyd's authors did not write.
//
//   node vrchat_receiver.js OUT_FILE PORT_FILE [IDLE_EXIT_MS]
//
// Binds UDP 127.0.0.1 on a free port and writes the port number to PORT_FILE (complete when
// the file exists: written to PORT_FILE.tmp, then renamed). Every packet it receives is
// (osc.js's "osc" event: one top-level packet) written to OUT_FILE as one JSON line, its trackers converted back to bodyd's space by the
// definitions in docs/outputs.md (written here from the doc, not from bodyd's code):
//   position bodyd = (x, y, -z) of the Unity position;
//   rotation: Unity's Quaternion.Euler(x, y, z) = Ry(y) * Rx(x) * Rz(z), then the mirror
//             (qx, qy, qz, qw) -> (-qx, -qy, qz, qw).
// {"bundle": true, "trackers": {"1": {"p": [..], "q": [x, y, z, w]}, ..., "head": {...}},
//  "addresses": [...], "bad": ["why", ...]}
// Exits 0 after IDLE_EXIT_MS (default 1500) without a packet, once at least one came, or
// 30 s after start.
'use strict';
const fs = require('fs');
const osc = require('osc');

const outPath = process.argv[2];
const portPath = process.argv[3];
const idleExitMs = Number(process.argv[4] || 1500);
const out = fs.openSync(outPath, 'w');

function axisAngle(axis, deg) {
  const h = (deg * Math.PI) / 360;
  const s = Math.sin(h);
  return [axis[0] * s, axis[1] * s, axis[2] * s, Math.cos(h)];
}

function mul(a, b) {  // Hamilton product, (x, y, z, w)
  const [ax, ay, az, aw] = a;
  const [bx, by, bz, bw] = b;
  return [
    aw * bx + ax * bw + ay * bz - az * by,
    aw * by - ax * bz + ay * bw + az * bx,
    aw * bz + ax * by - ay * bx + az * bw,
    aw * bw - ax * bx - ay * by - az * bz,
  ];
}

function unityEulerToBodydQuat(e) {
  const q = mul(mul(axisAngle([0, 1, 0], e[1]), axisAngle([1, 0, 0], e[0])), axisAngle([0, 0, 1], e[2]));
  return [-q[0], -q[1], q[2], q[3]];
}

let last = 0;
let count = 0;
const started = Date.now();
const port = new osc.UDPPort({localAddress: '127.0.0.1', localPort: 0, metadata: true});

port.on('ready', () => {
  // Room for a second of bundles while a loaded machine does not schedule us (capped by the
  // kernel's net.core.rmem_max).
  try {
    port.socket.setRecvBufferSize(4 * 1024 * 1024);
  } catch (e) {
    // keep the default size
  }
  fs.writeFileSync(portPath + '.tmp', String(port.socket.address().port));
  fs.renameSync(portPath + '.tmp', portPath);
});

port.on('osc', (packet) => {
  last = Date.now();
  ++count;
  const record = {bundle: Array.isArray(packet.packets), trackers: {}, addresses: [], bad: []};
  const messages = record.bundle ? packet.packets : [packet];
  const parts = {};
  for (const m of messages) {
    record.addresses.push(m.address);
    const match = /^\/tracking\/trackers\/(\d+|head)\/(position|rotation)$/.exec(m.address || '');
    if (!match) {
      record.bad.push('unexpected address ' + m.address);
      continue;
    }
    if (m.args.length !== 3 || m.args.some((a) => a.type !== 'f')) {
      record.bad.push(m.address + ': expected three floats (type tags fff)');
      continue;
    }
    parts[match[1]] = parts[match[1]] || {};
    parts[match[1]][match[2]] = m.args.map((a) => a.value);
  }
  for (const [slot, v] of Object.entries(parts)) {
    if (!v.position || !v.rotation) {
      record.bad.push('tracker ' + slot + ' without both position and rotation');
      continue;
    }
    record.trackers[slot] = {p: [v.position[0], v.position[1], -v.position[2]], q: unityEulerToBodydQuat(v.rotation)};
  }
  fs.writeSync(out, JSON.stringify(record) + '\n');
});

port.on('error', (e) => {
  fs.writeSync(out, JSON.stringify({error: String(e && e.message ? e.message : e)}) + '\n');
});

port.open();

setInterval(() => {
  const now = Date.now();
  if ((count > 0 && now - last > idleExitMs) || now - started > 30000) {
    fs.closeSync(out);
    process.exit(0);
  }
}, 100);
