// handsim teleop page: streams the tracked hand to the teleop loop and draws the simulation.
//
// - In a headset (Enter VR / Enter AR): every XR frame, the WebXR Hand Input joints of the
//   chosen hand (?hand=right, default; ?hand=both: each hand, as its own packet) go to the loop
//   as a 'webxr25' packet; the scene that the loop streams back (glb, then body poses per
//   control step) is drawn where the operator's hand is, the physical hand(s) over the real
//   one(s), each tracked hand as a cyan ghost.
// - In a browser without a headset: the same scene with an orbit camera (drag to turn, wheel to
//   zoom); the recording given to 'serve --replay' is replayed into the loop.
// - ?xrtest=1 loads xr_emulation.js (an emulated headset with a scripted hand) for tests.
import * as THREE from "three";
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";

const params = new URLSearchParams(location.search);
if (params.has("xrtest")) await import("./xr_emulation.js");

// WebXR Hand Input joint order (XRHandJoint), the 'webxr25' stream format.
const JOINTS = [
  "wrist",
  "thumb-metacarpal", "thumb-phalanx-proximal", "thumb-phalanx-distal", "thumb-tip",
  ...["index-finger", "middle-finger", "ring-finger", "pinky-finger"].flatMap((f) => [
    `${f}-metacarpal`, `${f}-phalanx-proximal`, `${f}-phalanx-intermediate`,
    `${f}-phalanx-distal`, `${f}-tip`]),
];
// Bones of handsim's 21 keypoints (wrist 0; thumb 1-4; index 5-8; middle; ring; little).
const BONES = [0, 1, 2, 3, 4].flatMap((f) => {
  const base = f === 0 ? 1 : 1 + 4 * f;
  return [[0, base], [base, base + 1], [base + 1, base + 2], [base + 2, base + 3]];
});
const GHOST_COLOR = 0x22d3ee;

const state = {
  seq: 0, sent: 0, ws: null, config: null, done: false, mode: "browser",
  scenesLoaded: 0, statesReceived: 0, statesApplied: 0, framesRendered: 0, lastState: null,
  errors: [], hold: false, connections: 0,
};
window.handsim = state;  // read by tests
window.addEventListener("error", (e) => state.errors.push(String(e.message)));
window.addEventListener("unhandledrejection", (e) => state.errors.push(String(e.reason)));
const statusEl = document.getElementById("status");
const status = (text) => { statusEl.textContent = text; };

// -- the view -----------------------------------------------------------------------------
const renderer = new THREE.WebGLRenderer({ antialias: true, alpha: true });
renderer.setPixelRatio(window.devicePixelRatio);
renderer.setSize(window.innerWidth, window.innerHeight);
renderer.xr.enabled = true;
renderer.xr.setReferenceSpaceType("local-floor");
document.body.appendChild(renderer.domElement);

const background = new THREE.Color(0x1d1f24);
const scene = new THREE.Scene();
scene.background = background;
scene.add(new THREE.HemisphereLight(0xffffff, 0x404040, 2.2));
const sun = new THREE.DirectionalLight(0xffffff, 1.8);
sun.position.set(0.6, 2.0, 1.2);
scene.add(sun);

// placement (view <- MuJoCo world): identity in the browser; in a headset it moves the world
// so the stream's anchor is undone and the physical hand lies over the operator's hand.
const placement = new THREE.Group();
scene.add(placement);
// MuJoCo's +z up -> three.js's +y up (the glb carries the same turn in its node 'y_up').
const world = new THREE.Group();
world.rotation.x = -Math.PI / 2;
placement.add(world);

const camera = new THREE.PerspectiveCamera(50, window.innerWidth / window.innerHeight, 0.01, 50);
camera.position.set(0.35, 0.55, 0.75);  // MuJoCo (0.35, -0.75, 0.55): in front, above
const controls = new OrbitControls(camera, renderer.domElement);
controls.target.set(0, 0.12, 0.12);
controls.update();
window.addEventListener("resize", () => {
  if (renderer.xr.isPresenting) return;
  camera.aspect = window.innerWidth / window.innerHeight;
  camera.updateProjectionMatrix();
  renderer.setSize(window.innerWidth, window.innerHeight);
});

// The ghosts: the tracked keypoints (after the loop's faults and filter), drawn over everything;
// one per hand the state carries ("tracked": the first hand; "tracked_hands": by side).
const ghostMaterial = new THREE.MeshBasicMaterial({
  color: GHOST_COLOR, transparent: true, opacity: 0.7, depthTest: false });
function makeGhost() {
  const group = new THREE.Group();
  const joints = Array.from({ length: 21 }, () => {
    const m = new THREE.Mesh(new THREE.SphereGeometry(0.006, 12, 8), ghostMaterial);
    m.renderOrder = 10;
    group.add(m);
    return m;
  });
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute("position", new THREE.BufferAttribute(new Float32Array(BONES.length * 6), 3));
  const bones = new THREE.LineSegments(geometry, new THREE.LineBasicMaterial({
    color: GHOST_COLOR, transparent: true, opacity: 0.7, depthTest: false }));
  bones.renderOrder = 10;
  group.add(bones);
  group.visible = false;
  world.add(group);
  return { group, joints, geometry, show: true };
}
const ghosts = { first: makeGhost() };  // "first": doc.tracked; a side: doc.tracked_hands[side]

// Draw one ghost between the tracked keypoints of two states (null rows are untracked).
function drawGhost(g, rowsA, rowsB, alpha) {
  const tracked = rowsB.map((q, j) => {
    const r = rowsA ? rowsA[j] : null;
    return q && r ? q.map((v, c) => r[c] + alpha * (v - r[c])) : q;
  });
  const lines = g.geometry.attributes.position;
  tracked.forEach((q, j) => {
    g.joints[j].visible = q !== null;
    if (q) g.joints[j].position.set(q[0], q[1], q[2]);
  });
  BONES.forEach(([i, j], k) => {
    const qi = tracked[i] || tracked[j] || [0, 0, 0];
    const qj = tracked[j] || qi;
    lines.setXYZ(2 * k, qi[0], qi[1], qi[2]);
    lines.setXYZ(2 * k + 1, qj[0], qj[1], qj[2]);
  });
  lines.needsUpdate = true;
  g.group.visible = tracked.some((q) => q !== null) && state.showGhost !== false && g.show;
}

// -- the scene and state from the loop ----------------------------------------------------
const loader = new GLTFLoader();
let sceneHeader = null;  // the header of the glb that arrives next
let current = null;  // { id, root, nodes: [Object3D per body], names: [body names] }

function bodyGroup(name) {
  if (name === "world") return "table";
  if (/^[rl]h_/.test(name)) return "hand";
  return "objects";
}

function loadScene(header, buffer) {
  loader.parse(buffer, "", (gltf) => {
    if (current) {
      // A new scene per reset would otherwise keep every old one on the GPU.
      placement.remove(current.root);
      current.root.traverse((o) => {
        if (o.geometry) o.geometry.dispose();
        if (o.material) o.material.dispose();
      });
    }
    const root = gltf.scene;  // its node y_up turns MuJoCo's world like `world` does
    const nodes = header.bodies.map((name) =>
      root.getObjectByName(THREE.PropertyBinding.sanitizeNodeName(name)) || null);
    placement.add(root);
    current = { id: header.scene_id, root, nodes, names: header.bodies };
    state.scenesLoaded += 1;
    if (!renderer.xr.isPresenting) {
      // Aim the orbit camera at the hand.
      const palm = nodes[header.bodies.findIndex((n) => /^[rl]h_palm$/.test(n))];
      if (palm) {
        palm.updateWorldMatrix(true, false);
        controls.target.copy(palm.getWorldPosition(new THREE.Vector3()));
        controls.update();
      }
    }
  }, (err) => state.errors.push(String(err)));
}

// Display-rate motion: states come once per control step (50 Hz with the tasks' defaults),
// frames at the display's rate (72-120 Hz). The view is drawn one state period in the past,
// interpolated between the two states around that time, on the simulation's clock. Its offset
// to this page's clock follows an early arrival at once and a late one by a third, so network
// jitter hardly shakes it and a loop that falls behind real time is followed.
// ?interp=0 draws the newest state as it comes instead.
const interpolate = params.get("interp") !== "0";
const history = [];  // { doc, t (sim ms), at (page ms) }, oldest first
let clockOffsetMs = null;  // page time - simulation time
const qa = new THREE.Quaternion(), qb = new THREE.Quaternion();

function receiveState(doc) {
  const last = history[history.length - 1];
  // A new episode or scene restarts the clock.
  if (last && (doc.scene_id !== last.doc.scene_id || doc.t_s <= last.doc.t_s)) {
    history.length = 0;
    clockOffsetMs = null;
  }
  const entry = { doc, t: doc.t_s * 1000, at: performance.now() };
  history.push(entry);
  if (history.length > 16) history.shift();
  const sample = entry.at - entry.t;
  clockOffsetMs = clockOffsetMs === null || sample < clockOffsetMs ? sample
    : clockOffsetMs + (sample - clockOffsetMs) / 3;
  state.statesReceived += 1;
  state.lastState = doc;
}

function statesAt(now) {
  const n = history.length;
  if (n === 0) return null;
  const newest = history[n - 1];
  if (!interpolate || n < 2) return [newest, newest, 0];
  const t = now - clockOffsetMs - (newest.t - history[n - 2].t);
  if (t >= newest.t) return [newest, newest, 0];
  for (let i = n - 2; i >= 0; i--) {
    if (history[i].t <= t) {
      const a = history[i], b = history[i + 1];
      return [a, b, (t - a.t) / (b.t - a.t)];
    }
  }
  return [history[0], history[0], 0];
}

function applyState(a, b, alpha) {
  const doc = b;
  if (!current || doc.scene_id !== current.id || a.scene_id !== doc.scene_id) return;
  const pa = a.poses, p = doc.poses;
  current.nodes.forEach((node, i) => {
    if (!node) return;
    const k = 7 * i;
    node.position.set(pa[k] + alpha * (p[k] - pa[k]), pa[k + 1] + alpha * (p[k + 1] - pa[k + 1]),
      pa[k + 2] + alpha * (p[k + 2] - pa[k + 2]));
    qa.set(pa[k + 4], pa[k + 5], pa[k + 6], pa[k + 3]);
    qb.set(p[k + 4], p[k + 5], p[k + 6], p[k + 3]);
    node.quaternion.slerpQuaternions(qa, qb, alpha);
  });
  drawGhost(ghosts.first, a.tracked, doc.tracked, alpha);
  // Two hands: the hands after the first (the state names them by side).
  for (const [side, rows] of Object.entries(doc.tracked_hands || {})) {
    if (!ghosts[side]) ghosts[side] = makeGhost();
    drawGhost(ghosts[side], (a.tracked_hands || {})[side], rows, alpha);
  }
  if (renderer.xr.isPresenting) {
    // xr = R_y_up (world - offset): the anchor the loop added is taken off again.
    const o = doc.offset_m;
    placement.position.set(-o[0], -o[2], o[1]);
  }
  if (doc !== state.appliedState) { state.appliedState = doc; state.statesApplied += 1; }
  state.drawn = { from_step: a.step, to_step: doc.step, alpha };
}

// Where things are in the view (tests): the palm body and the ghost's wrist, three.js world.
state.where = () => {
  const out = {};
  if (current) {
    const i = current.names.findIndex((n) => /^[rl]h_palm$/.test(n));
    if (i >= 0) out.palm = current.nodes[i].getWorldPosition(new THREE.Vector3()).toArray();
    const left = current.names.indexOf("lh_palm");
    if (left >= 0 && left !== i) {
      out.leftPalm = current.nodes[left].getWorldPosition(new THREE.Vector3()).toArray();
    }
  }
  out.ghostWrist = ghosts.first.joints[0].getWorldPosition(new THREE.Vector3()).toArray();
  if (ghosts.left) {
    out.leftGhostWrist = ghosts.left.joints[0].getWorldPosition(new THREE.Vector3()).toArray();
  }
  out.placement = placement.position.toArray();
  return out;
};

// Tests hide parts to see which pixels they cover: "hand", "objects", "table", "ghost" (every
// ghost), "ghost:<side>" (one hand's ghost of a two-hand state).
state.setVisible = (part, visible) => {
  if (part === "ghost") {
    state.showGhost = visible;
    Object.values(ghosts).forEach((g) => { g.group.visible = visible; });
    return;
  }
  if (part.startsWith("ghost:")) {
    const g = ghosts[part.slice(6)];
    if (g) { g.show = visible; g.group.visible = visible; }
    return;
  }
  if (!current) return;
  current.nodes.forEach((node, i) => {
    if (node && bodyGroup(current.names[i]) === part) node.visible = visible;
  });
};

// -- the WebSocket ------------------------------------------------------------------------
function send(doc) {
  if (!state.ws || state.ws.readyState !== WebSocket.OPEN) return false;
  doc.seq = state.seq++;
  state.ws.send(JSON.stringify(doc));
  state.sent += 1;
  return true;
}

// The loop may start after the page, or end and start again: the page keeps (re)connecting.
function openSocket(url, onOpen) {
  const ws = new WebSocket(url);
  ws.binaryType = "arraybuffer";
  ws.onopen = () => {
    state.ws = ws;
    state.connections += 1;
    // A new loop numbers its scenes again: nothing is drawn from it before its own scene.
    sceneHeader = null;
    history.length = 0;
    clockOffsetMs = null;
    if (current) current.id = null;
    ws.send(JSON.stringify({ type: "subscribe" }));
    status(`connected to ${url}`);
    if (onOpen) onOpen();
  };
  ws.onclose = () => {
    if (state.ws === ws) state.ws = null;
    status(`waiting for the loop at ${url} ('handsim teleop live --websocket ...')`);
    setTimeout(() => openSocket(url), 1000);
  };
  ws.onmessage = (event) => {
    if (event.data instanceof ArrayBuffer) {
      if (sceneHeader) loadScene(sceneHeader, event.data);
      sceneHeader = null;
      return;
    }
    const doc = JSON.parse(event.data);
    if (doc.type === "scene") sceneHeader = doc;
    else if (doc.type === "state") receiveState(doc);
  };
}

async function connect() {
  state.config = await (await fetch("config.json")).json();
  const port = params.get("ws") || state.config.ws_port;
  const url = `ws://${location.hostname}:${port}`;
  document.getElementById("target").textContent = url;
  status(`waiting for the loop at ${url}`);
  return new Promise((resolve) => openSocket(url, resolve));
}

async function replay() {
  const rec = await (await fetch("replay.json")).json();
  const dt = 1000 / rec.fps;
  const t0 = performance.now();
  // A two-hand recording lists both hands: each frame of each hand is its own packet.
  const tracks = rec.hands || [{ hand: rec.hand, frames: rec.frames }];
  const total = tracks.reduce((n, track) => n + track.frames.length, 0);
  const steps = Math.max(...tracks.map((track) => track.frames.length));
  for (let i = 0; i < steps; i++) {
    const wait = t0 + i * dt - performance.now();
    if (wait > 0) await new Promise((r) => setTimeout(r, wait));
    for (const track of tracks) {
      if (i >= track.frames.length) continue;
      send({ t: track.frames[i].t, format: "handsim21", up_axis: "z", hand: track.hand,
             keypoints: track.frames[i].keypoints });
    }
    status(`replay: sent ${state.sent} of ${total} frames`);
  }
  state.done = true;
  document.title = `handsim teleop: replay done, ${state.sent} sent`;
}

// -- the headset ----------------------------------------------------------------------------
const wanted = params.get("hand") || "right";

function streamHand(time, frame) {
  const space = renderer.xr.getReferenceSpace();
  for (const source of frame.session.inputSources) {
    if (!source.hand || (wanted !== "both" && source.handedness !== wanted)) continue;
    const keypoints = [], radii = [];
    for (const name of JOINTS) {
      const pose = frame.getJointPose(source.hand.get(name), space);
      if (pose) {
        const p = pose.transform.position;
        keypoints.push([p.x, p.y, p.z]);
        radii.push(pose.radius);
      } else { keypoints.push(null); radii.push(null); }
    }
    const hand = source.handedness;  // each hand its own packet, routed by its 'hand'
    if (send({ t: time / 1000, format: "webxr25", up_axis: "y", hand, keypoints, radii })) {
      status(`${state.mode}: sent ${state.sent} frames, ${state.statesReceived} states back`);
    }
  }
}

async function enterXR(mode) {
  const session = await navigator.xr.requestSession(mode, {
    optionalFeatures: ["local-floor", "hand-tracking"] });
  state.mode = mode;
  // Passthrough: the room is the background.
  scene.background = mode === "immersive-ar" ? null : background;
  state.passthrough = scene.background === null;
  session.addEventListener("end", () => {
    state.mode = "browser";
    scene.background = background;
    state.passthrough = false;
    placement.position.set(0, 0, 0);
  });
  await renderer.xr.setSession(session);
}

renderer.setAnimationLoop((time, frame) => {
  if (frame) streamHand(time, frame);
  // hold: tests freeze the view (new states wait) to compare screenshots.
  const around = state.hold ? null : statesAt(performance.now());
  if (around) applyState(around[0].doc, around[1].doc, around[2]);
  if (!renderer.xr.isPresenting) controls.update();
  renderer.render(scene, camera);
  state.framesRendered += 1;
});

(async () => {
  try { await connect(); } catch (e) { status(String(e)); return; }
  const replayButton = document.getElementById("replay");
  if (state.config.has_replay) {
    replayButton.disabled = false;
    replayButton.onclick = replay;
  }
  let headset = false;
  for (const [id, mode] of [["vr", "immersive-vr"], ["ar", "immersive-ar"]]) {
    if (navigator.xr && await navigator.xr.isSessionSupported(mode).catch(() => false)) {
      const button = document.getElementById(id);
      button.disabled = false;
      button.onclick = () => enterXR(mode).catch((e) => status(String(e)));
      headset = true;
    }
  }
  if (params.has("enter")) {
    // Tests (and kiosks) enter at once: ?enter=immersive-vr or immersive-ar.
    await enterXR(params.get("enter")).catch((e) => { state.errors.push(String(e)); status(String(e)); });
  } else if (!headset && state.config.has_replay && params.get("replay") !== "0") {
    await replay();  // no headset: replay the recording
  } else if (!headset) {
    status("connected; no WebXR headset and no recording to replay");
  }
})();
