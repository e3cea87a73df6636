// bodyd live viewer: draws the pose stream pushed by bodyd-viewer-bridge over a WebSocket
// (messages: docs/viewer.md) as a 3D skeleton with three.js. Coordinates are bodyd's: metres,
// +Y up, the floor at y = 0 (docs/conventions.md), which is also three.js's convention.
import * as THREE from 'three';

const BODY_COLOUR = 0xff7f0e;     // bones and joints
const TRACKED_COLOUR = 0xd62728;  // Head, Hand_L, Hand_R
const TRACKED = new Set(['Head', 'Hand_L', 'Hand_R']);

const container = document.getElementById('view');
const statusEl = document.getElementById('status');

const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
renderer.setSize(container.clientWidth, container.clientHeight);
container.appendChild(renderer.domElement);

const scene = new THREE.Scene();
scene.background = new THREE.Color(0xf4f4f2);
// three.js r155 made light intensities physical; Debian's libjs-three (r111) predates that, so its
// lights are dimmed to give the same picture.
const LIGHT_SCALE = parseInt(THREE.REVISION, 10) >= 155 ? 1.0 : 0.45;
scene.add(new THREE.HemisphereLight(0xffffff, 0x888888, 2.0 * LIGHT_SCALE));
const sun = new THREE.DirectionalLight(0xffffff, 1.5 * LIGHT_SCALE);
sun.position.set(2, 4, 3);
scene.add(sun);
const grid = new THREE.GridHelper(10, 20, 0x999999, 0xcccccc);
scene.add(grid);

const camera = new THREE.PerspectiveCamera(40, container.clientWidth / container.clientHeight, 0.05, 100);
const target = new THREE.Vector3(0, 0.9, 0);
// The camera looks at the body from the front-right, 3.2 m away, and follows the hips.
const cameraOffset = new THREE.Vector3(1.6, 0.5, 2.8);
camera.position.copy(target).add(cameraOffset);
camera.lookAt(target);

const bodyMaterial = new THREE.MeshLambertMaterial({ color: BODY_COLOUR });
const trackedMaterial = new THREE.MeshLambertMaterial({ color: TRACKED_COLOUR });
const jointGeometry = new THREE.SphereGeometry(0.035, 16, 12);
const trackedGeometry = new THREE.SphereGeometry(0.055, 16, 12);
const boneGeometry = new THREE.CylinderGeometry(0.022, 0.022, 1, 10);  // unit length along +Y

// With ?hold-load in the URL the module (hence the page's load event) does not finish before the
// first pose is drawn and the first daemon status is shown (or 10 s have passed), so
// `chromium --headless --screenshot` captures a skeleton and `--dump-dom` a filled status panel
// (docs/viewer.md, tests/render/viewer_test.cpp).
// The load event waits for images in the document: a hidden one whose request the bridge holds
// until this page posts /api/page-ready (module scripts' top-level await does not delay load).
const holdLoad = new URLSearchParams(location.search).has('hold-load');
if (holdLoad) {
  const hold = document.createElement('img');
  hold.style.display = 'none';
  hold.alt = '';
  hold.src = '/hold';
  document.body.appendChild(hold);
}
let firstPoseDrawn, firstStatusShown;
const firstPose = new Promise((resolve) => { firstPoseDrawn = resolve; });
const firstStatus = new Promise((resolve) => { firstStatusShown = resolve; });

let skeleton = null;  // { names, parents, joints: [Mesh], bones: [{mesh, child, parent}] }
let poses = 0;        // poses drawn by this page
let lastSeq = null;   // the newest pose drawn
const UP = new THREE.Vector3(0, 1, 0);

function buildSkeleton(msg) {
  if (skeleton && skeleton.id === msg.skeleton_id) return;  // the same one again (a reconnect)
  if (skeleton) {
    for (const m of skeleton.joints) scene.remove(m);
    for (const b of skeleton.bones) scene.remove(b.mesh);
  }
  const s = { id: msg.skeleton_id, names: msg.names, parents: msg.parents, index: new Map(), joints: [], bones: [] };
  msg.names.forEach((name, i) => {
    s.index.set(name, i);
    // joint_Root is a ground-level reference, not a body joint: not drawn.
    const visible = name !== 'joint_Root';
    const tracked = TRACKED.has(name);
    const mesh = new THREE.Mesh(tracked ? trackedGeometry : jointGeometry, tracked ? trackedMaterial : bodyMaterial);
    mesh.visible = visible;
    scene.add(mesh);
    s.joints.push(mesh);
    const p = msg.parents[i];
    if (p >= 0 && msg.names[p] !== 'joint_Root' && visible) {
      const bone = new THREE.Mesh(boneGeometry, bodyMaterial);
      scene.add(bone);
      s.bones.push({ mesh: bone, child: i, parent: p });
    }
  });
  skeleton = s;
}

const a = new THREE.Vector3(), b = new THREE.Vector3(), d = new THREE.Vector3();

function showPose(msg) {
  if (!skeleton || msg.skeleton_id !== skeleton.id) return false;
  // joints: {name: [x, y, z]} when the bridge knows the skeleton, else [[x, y, z], ...] in skeleton order.
  const named = !Array.isArray(msg.joints);
  const pos = (i) => (named ? msg.joints[skeleton.names[i]] : msg.joints[i]);
  for (let i = 0; i < skeleton.joints.length; ++i) {
    const p = pos(i);
    if (p) skeleton.joints[i].position.set(p[0], p[1], p[2]);
  }
  for (const bone of skeleton.bones) {
    a.copy(skeleton.joints[bone.parent].position);
    b.copy(skeleton.joints[bone.child].position);
    d.subVectors(b, a);
    const length = d.length();
    bone.mesh.visible = length > 1e-4;
    if (!bone.mesh.visible) continue;
    bone.mesh.position.copy(a).addScaledVector(d, 0.5);
    bone.mesh.scale.set(1, length, 1);
    bone.mesh.quaternion.setFromUnitVectors(UP, d.normalize());
  }
  const hips = skeleton.index.get('Hips');
  if (hips !== undefined) {
    const h = skeleton.joints[hips].position;
    target.set(h.x, 0.9, h.z);
    camera.position.copy(target).add(cameraOffset);
    camera.lookAt(target);
    grid.position.set(Math.round(h.x), 0, Math.round(h.z));
  }
  return true;
}

function render() { renderer.render(scene, camera); }

// This page's own drawing rate: poses drawn per second of the browser's clock, over the last
// second or more. It is the page's, not the daemon's: a busy machine or a background tab draws
// fewer poses than bodyd publishes (the bridge sends only the newest), and the panel's
// "poses published per second" is bodyd's.
let drawnPerS = null;
let rateSince = { t: performance.now(), poses: 0 };
setInterval(() => {
  const now = performance.now();
  drawnPerS = (poses - rateSince.poses) / ((now - rateSince.t) / 1000);
  rateSince = { t: now, poses };
  statusEl.dataset.drawnPerS = fmt(drawnPerS, 1);
  if (statusEl.dataset.state === 'streaming') setStatus('streaming', streamingText());
}, 1000);

function streamingText() {
  return `pose ${lastSeq} · ${poses} drawn · this page draws ${fmt(drawnPerS, 1)} poses/s`;
}

function setStatus(state, text) {
  statusEl.dataset.state = state;
  statusEl.dataset.poses = String(poses);
  statusEl.dataset.drawnPerS = fmt(drawnPerS, 1);
  statusEl.textContent = text;
}

// ---- the daemon's status panel (the bridge's "status" message: docs/viewer.md) ----------------

const daemonEl = document.getElementById('daemon');
const summaryEl = document.getElementById('daemon-summary');
const sourcesEl = document.getElementById('sources');
const numbersEl = document.getElementById('numbers');
const resultEl = document.getElementById('action-result');

function cell(row, text, cls) {
  const td = row.insertCell();
  td.textContent = text;
  if (cls) td.className = cls;
  return td;
}

function fmt(x, digits = 0) { return typeof x === 'number' && isFinite(x) ? x.toFixed(digits) : '–'; }

function showStatus(msg) {
  firstStatusShown();
  const d = msg.daemon || {};
  const s = d.status;
  if (d.control === 'none') {
    daemonEl.dataset.daemonState = 'no-control';
    summaryEl.textContent = 'no control endpoint (bridge started with --control none)';
  } else if (!d.answered || !s) {
    daemonEl.dataset.daemonState = 'not-answering';
    summaryEl.textContent = `no answer from ${d.control}: ${d.error || 'no reply'} (is bodyd running?)`;
    summaryEl.className = 'bad';
  } else {
    daemonEl.dataset.daemonState = 'answering';
    summaryEl.className = '';
    summaryEl.textContent = `${s.method}${s.model ? ' · ' + s.model.split('/').pop() : ''} · up ${fmt(s.uptime_s)} s`;
  }
  sourcesEl.replaceChildren();
  numbersEl.replaceChildren();
  const addRow = (name, value) => {
    const row = numbersEl.insertRow();
    cell(row, name);
    cell(row, value, 'v');
  };
  // The daemon's pose rate is what it published, counted by the bridge from the stream's seq and
  // publish times (so neither the bridge's nor this page's speed enters it, and it is known with
  // --control none too); what this page draws per second is in the status line, labelled as the
  // page's (issue 43 item 16: one "poses per second" said neither whose rate it was nor how it was
  // counted).
  daemonEl.dataset.publishedPerS = fmt(msg.published_per_s, 1);
  addRow('poses published per second', fmt(msg.published_per_s, 1));
  addRow('poses lost on the way here', fmt(msg.dropped));
  if (!s) return;
  const sources = s.sources || [];
  daemonEl.dataset.sources = String(sources.length);
  for (const src of sources) {
    const row = sourcesEl.insertRow();
    const state = src.finished ? 'finished' : src.connected ? 'connected' : 'disconnected';
    cell(row, src.name, 'name').title = src.name;
    cell(row, state, src.connected || src.finished ? '' : 'bad');
    cell(row, `${fmt(src.rate_hz)} Hz`, 'v');
    if (src.last_error) cell(sourcesEl.insertRow(), src.last_error, 'bad').colSpan = 3;
  }
  const lat = s.latency_us || {}, rec = s.reconstruct_us || {};
  daemonEl.dataset.latencyP99Us = fmt(lat.p99);
  addRow('poses sent', fmt(s.frames_out));
  addRow('samples dropped (queue full)', fmt(s.samples_dropped));
  addRow('poses not sent', fmt(s.sends_failed));
  addRow('latency p50 / p99 (ms)', `${fmt(lat.p50 / 1000, 2)} / ${fmt(lat.p99 / 1000, 2)}`);
  addRow('reconstruction p50 / p99 (ms)', `${fmt(rec.p50 / 1000, 2)} / ${fmt(rec.p99 / 1000, 2)}`);
  addRow('head height (m)', `${fmt(s.head_height_m, 3)} ${s.height_calibrated ? '(calibrated)' : '(model default)'}`);
  // For tests (docs/viewer.md): whether anything in the panel is wider than the panel.
  daemonEl.dataset.overflow = String(daemonEl.scrollWidth > daemonEl.clientWidth);
}

async function post(path, body) {
  resultEl.textContent = '…';
  try {
    const response = await fetch(path, { method: 'POST', headers: { 'Content-Type': 'application/json' },
                                         body: JSON.stringify(body) });
    const reply = await response.json();
    resultEl.className = reply.ok ? '' : 'bad';
    resultEl.textContent = reply.ok ? 'done' : `refused: ${reply.error}`;
  } catch (e) {
    resultEl.className = 'bad';
    resultEl.textContent = `no answer from the bridge: ${e}`;
  }
}

document.getElementById('calibrate').addEventListener('click', () => post('/api/calibrate', { from: 'head' }));
document.getElementById('reset').addEventListener('click', () => post('/api/reset', {}));

// One message of the bridge (docs/viewer.md): from the WebSocket, or one of those the bridge wrote
// into the page as it served it (served: true).
function onMessage(msg, served) {
  if (msg.type === 'skeleton') {
    buildSkeleton(msg);
  } else if (msg.type === 'status') {
    showStatus(msg);
  } else if (msg.type === 'pose') {
    if (showPose(msg)) {
      ++poses;
      lastSeq = msg.seq;
      render();
      firstPoseDrawn();
      // seq and count only: the pose's t_ns is the trackers' clock (for live sources the
      // daemon's CLOCK_MONOTONIC, time since boot), which means nothing to a viewer.
      if (served) setStatus('connecting', `pose ${msg.seq} (the newest when the page was served) · connecting…`);
      else setStatus('streaming', streamingText());
    } else {
      setStatus('connected', 'waiting for the skeleton');
    }
  }
}

function connect() {
  const ws = new WebSocket(`ws://${location.host}/ws`);
  ws.onopen = () => setStatus('connected', lastSeq === null ? 'connected, waiting for poses'
                                                             : `pose ${lastSeq} · connected, waiting for new poses`);
  ws.onmessage = (event) => onMessage(JSON.parse(event.data), false);
  ws.onclose = () => {
    setStatus('disconnected', 'disconnected from the bridge, retrying…');
    setTimeout(connect, 1000);
  };
}

window.addEventListener('resize', () => {
  camera.aspect = container.clientWidth / container.clientHeight;
  camera.updateProjectionMatrix();
  renderer.setSize(container.clientWidth, container.clientHeight);
  render();
});

// What the bridge wrote into the page (the newest skeleton, pose and status it had), drawn before
// the load event: the first paint, and a screenshot taken at the load event, show the body and the
// panel without waiting for the WebSocket (issue 43 item 16).
const initialElement = document.getElementById('initial-state');
const initial = initialElement ? JSON.parse(initialElement.textContent || '{}') : {};
for (const msg of [initial.skeleton, initial.pose, initial.status]) {
  if (msg) onMessage(msg, true);
}
render();
connect();
if (holdLoad) {
  await Promise.race([Promise.all([firstPose, firstStatus]), new Promise((resolve) => setTimeout(resolve, 10000))]);
  render();
  await fetch('/api/page-ready', { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: '{}' });
}
