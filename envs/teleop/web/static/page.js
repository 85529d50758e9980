// handsim teleop page: streams the tracked hand to the teleop loop and draws the simulation.
//
// - In a headset (Enter VR / Enter AR): every XR frame, the WebXR Hand Input joints of the
//   chosen hand (?hand=right, default) go to the loop as a 'webxr25' packet; the scene that the
//   loop streams back (glb, then body poses per control step) is drawn where the operator's hand
//   is, the physical hand over the real one, the tracked hand as a cyan ghost.
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
  errors: [], hold: false,
};
window.handsim = state;  // read by tests
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

// The ghost: the tracked keypoints (after the loop's faults and filter), drawn over everything.
const ghost = new THREE.Group();
const ghostMaterial = new THREE.MeshBasicMaterial({
  color: GHOST_COLOR, transparent: true, opacity: 0.7, depthTest: false });
const ghostJoints = Array.from({ length: 21 }, () => {
  const m = new THREE.Mesh(new THREE.SphereGeometry(0.006, 12, 8), ghostMaterial);
  m.renderOrder = 10;
  ghost.add(m);
  return m;
});
const boneGeometry = new THREE.BufferGeometry();
boneGeometry.setAttribute("position", new THREE.BufferAttribute(new Float32Array(BONES.length * 6), 3));
const ghostBones = new THREE.LineSegments(boneGeometry, new THREE.LineBasicMaterial({
  color: GHOST_COLOR, transparent: true, opacity: 0.7, depthTest: false }));
ghostBones.renderOrder = 10;
ghost.add(ghostBones);
ghost.visible = false;
world.add(ghost);

// -- the scene and state from the loop ----------------------------------------------------
const loader = new GLTFLoader();
let sceneHeader = null;  // the header of the glb that arrives next
let current = null;  // { id, root, nodes: [Object3D per body], groups }

function bodyGroup(name) {
  if (name === "world") return "table";
  if (/^[rl]h_/.test(name)) return "hand";
  return "objects";
}

function loadScene(header, buffer) {
  loader.parse(buffer, "", (gltf) => {
    if (current) placement.remove(current.root);
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

function applyState(doc) {
  if (!current || doc.scene_id !== current.id) return;
  const p = doc.poses;
  current.nodes.forEach((node, i) => {
    if (!node) return;
    node.position.set(p[7 * i], p[7 * i + 1], p[7 * i + 2]);
    node.quaternion.set(p[7 * i + 4], p[7 * i + 5], p[7 * i + 6], p[7 * i + 3]);
  });
  const lines = boneGeometry.attributes.position;
  doc.tracked.forEach((q, j) => {
    ghostJoints[j].visible = q !== null;
    if (q) ghostJoints[j].position.set(q[0], q[1], q[2]);
  });
  BONES.forEach(([a, b], k) => {
    const qa = doc.tracked[a] || doc.tracked[b] || [0, 0, 0];
    const qb = doc.tracked[b] || qa;
    lines.setXYZ(2 * k, qa[0], qa[1], qa[2]);
    lines.setXYZ(2 * k + 1, qb[0], qb[1], qb[2]);
  });
  lines.needsUpdate = true;
  ghost.visible = doc.tracked.some((q) => q !== null) && state.showGhost !== false;
  if (renderer.xr.isPresenting) {
    // xr = R_y_up (world - offset): the anchor the loop added is taken off again.
    const o = doc.offset_m;
    placement.position.set(-o[0], -o[2], o[1]);
  }
  state.statesApplied += 1;
}

// Where things are in the view (tests): the palm body and the ghost's wrist, three.js world.
state.where = () => {
  const out = {};
  if (current) {
    const i = current.names.findIndex((n) => /^[rl]h_palm$/.test(n));
    if (i >= 0) out.palm = current.nodes[i].getWorldPosition(new THREE.Vector3()).toArray();
  }
  out.ghostWrist = ghostJoints[0].getWorldPosition(new THREE.Vector3()).toArray();
  out.placement = placement.position.toArray();
  return out;
};

// Tests hide parts to see which pixels they cover: "hand", "objects", "table", "ghost".
state.setVisible = (part, visible) => {
  if (part === "ghost") { state.showGhost = visible; ghost.visible = visible; return; }
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

async function connect() {
  state.config = await (await fetch("config.json")).json();
  const port = params.get("ws") || state.config.ws_port;
  const url = `ws://${location.hostname}:${port}`;
  document.getElementById("target").textContent = url;
  return new Promise((resolve, reject) => {
    const ws = new WebSocket(url);
    ws.binaryType = "arraybuffer";
    ws.onopen = () => {
      state.ws = ws;
      ws.send(JSON.stringify({ type: "subscribe" }));
      resolve(ws);
    };
    ws.onerror = () => reject(new Error(`cannot connect to ${url}`));
    ws.onmessage = (event) => {
      if (event.data instanceof ArrayBuffer) {
        if (sceneHeader) loadScene(sceneHeader, event.data);
        sceneHeader = null;
        return;
      }
      const doc = JSON.parse(event.data);
      if (doc.type === "scene") sceneHeader = doc;
      else if (doc.type === "state") { state.statesReceived += 1; state.lastState = doc; }
    };
  });
}

async function replay() {
  const rec = await (await fetch("replay.json")).json();
  const dt = 1000 / rec.fps;
  const t0 = performance.now();
  for (let i = 0; i < rec.frames.length; i++) {
    const wait = t0 + i * dt - performance.now();
    if (wait > 0) await new Promise((r) => setTimeout(r, wait));
    send({ t: rec.frames[i].t, format: "handsim21", up_axis: "z", hand: rec.hand,
           keypoints: rec.frames[i].keypoints });
    status(`replay: sent ${state.sent} of ${rec.frames.length} frames`);
  }
  state.done = true;
  document.title = `handsim teleop: replay done, ${state.sent} sent`;
}

// -- the headset ----------------------------------------------------------------------------
const wanted = params.get("hand") || "right";

function streamHand(time, frame) {
  const space = renderer.xr.getReferenceSpace();
  for (const source of frame.session.inputSources) {
    if (!source.hand || source.handedness !== wanted) continue;
    const keypoints = [], radii = [];
    for (const name of JOINTS) {
      const pose = frame.getJointPose(source.hand.get(name), space);
      if (pose) {
        const p = pose.transform.position;
        keypoints.push([p.x, p.y, p.z]);
        radii.push(pose.radius);
      } else { keypoints.push(null); radii.push(null); }
    }
    if (send({ t: time / 1000, format: "webxr25", up_axis: "y", hand: wanted, keypoints, radii })) {
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
  session.addEventListener("end", () => {
    state.mode = "browser";
    scene.background = background;
    placement.position.set(0, 0, 0);
  });
  await renderer.xr.setSession(session);
}

renderer.setAnimationLoop((time, frame) => {
  if (frame) streamHand(time, frame);
  const doc = state.lastState;
  // hold: tests freeze the view (new states wait) to compare screenshots.
  if (doc && doc !== state.appliedState && !state.hold) { applyState(doc); state.appliedState = doc; }
  if (!renderer.xr.isPresenting) controls.update();
  renderer.render(scene, camera);
  state.framesRendered += 1;
});

(async () => {
  try { await connect(); } catch (e) { status(String(e)); return; }
  status("connected");
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
