// handsim test hook: an emulated WebXR device with one scripted right hand (or two hands).
//
// Loaded by the teleop page only when its URL has ?xrtest=1, before three.js builds its
// renderer. It replaces navigator.xr with a device that supports 'immersive-vr' and
// 'immersive-ar', whose sessions render into the page's own canvas (one view, the default
// framebuffer) from a fixed head pose, and whose one input source is a right hand (WebXR Hand
// Input, 25 joints) that sways 3 cm left and right at 0.5 Hz. So headless Chromium can enter a
// session, stream joints and render, and a screenshot shows what a headset would. With
// ?xrhands=both a left hand (the right one mirrored, 20 cm to its left) is a second input source.

// A relaxed right hand, mm from the wrist, in the XR frame (x right, y up, z toward the viewer):
// palm down, fingers forward. handsim 21-keypoint order; made with
//   ForwardKinematics(hand_params()).keypoints(gesture("relaxed")), hand frame -> XR
//   (x radial -> -x, y distal -> -z, z palmar -> -y).
const HAND21_MM = [
  [0, 0, 0], [-17, -11, -10], [-37, -35, -45], [-48, -56, -74], [-51, -73, -98],
  [-29, -4, -82], [-29, -21, -129], [-29, -42, -146], [-29, -59, -153],
  [-7, 0, -84], [-7, -22, -132], [-8, -50, -148], [-9, -70, -150],
  [14, -2, -79], [15, -27, -122], [13, -56, -133], [11, -76, -131],
  [29, -8, -74], [30, -30, -106], [28, -52, -110], [24, -68, -105],
];
const WRIST_XR_M = [0.0, 1.05, -0.3];  // where the hand is held, metres (local-floor)
const HEAD_XR_M = [0.32, 1.36, 0.0];  // the viewer's eye, to the right (the arm hides less)
const LOOK_AT_XR_M = [0.02, 0.92, -0.45];
const FOV_Y_RAD = (65 * Math.PI) / 180;
const TWO_HANDS = new URLSearchParams(location.search).get("xrhands") === "both";
const LEFT_OFFSET_XR_M = -0.2;  // the left wrist from the right one, along x

const JOINTS = [
  "wrist",
  "thumb-metacarpal", "thumb-phalanx-proximal", "thumb-phalanx-distal", "thumb-tip",
  ...["index-finger", "middle-finger", "ring-finger", "pinky-finger"].flatMap((f) => [
    `${f}-metacarpal`, `${f}-phalanx-proximal`, `${f}-phalanx-intermediate`,
    `${f}-phalanx-distal`, `${f}-tip`]),
];

// The 25 WebXR joints from the 21 keypoints (a finger's metacarpal joint, which handsim's 21
// do not have, lies a quarter of the way from the wrist to its MCP).
function handJoints(timeS, side = "right") {
  const sway = 0.03 * Math.sin(2 * Math.PI * 0.5 * timeS);
  // The left hand is the right one mirrored in x, beside it.
  const sx = side === "left" ? -1 : 1, dx = side === "left" ? LEFT_OFFSET_XR_M : 0;
  const at = (p) => [WRIST_XR_M[0] + dx + sway + (sx * p[0]) / 1000, WRIST_XR_M[1] + p[1] / 1000,
    WRIST_XR_M[2] + p[2] / 1000];
  const out = { wrist: at(HAND21_MM[0]) };
  ["thumb-metacarpal", "thumb-phalanx-proximal", "thumb-phalanx-distal", "thumb-tip"]
    .forEach((name, k) => { out[name] = at(HAND21_MM[1 + k]); });
  ["index-finger", "middle-finger", "ring-finger", "pinky-finger"].forEach((f, i) => {
    const mcp = HAND21_MM[5 + 4 * i];
    out[`${f}-metacarpal`] = at(mcp.map((v) => v / 4));
    ["phalanx-proximal", "phalanx-intermediate", "phalanx-distal", "tip"].forEach((s, k) => {
      out[`${f}-${s}`] = at(HAND21_MM[5 + 4 * i + k]);
    });
  });
  return out;
}

// Column-major 4x4 matrices, as WebXR gives them.
function lookAtMatrix(eye, target) {
  const sub = (a, b) => a.map((v, i) => v - b[i]);
  const norm = (a) => { const n = Math.hypot(...a); return a.map((v) => v / n); };
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
    a[0] * b[1] - a[1] * b[0]];
  const z = norm(sub(eye, target));  // the camera looks along -z
  const x = norm(cross([0, 1, 0], z));
  const y = cross(z, x);
  return new Float32Array([...x, 0, ...y, 0, ...z, 0, ...eye, 1]);
}
function invertRigid(m) {
  const r = [[m[0], m[1], m[2]], [m[4], m[5], m[6]], [m[8], m[9], m[10]]];  // columns
  const t = [m[12], m[13], m[14]];
  const out = new Float32Array(16);
  for (let i = 0; i < 3; i++) {
    for (let j = 0; j < 3; j++) out[4 * j + i] = r[i][j];  // transpose
    out[12 + i] = -(r[i][0] * t[0] + r[i][1] * t[1] + r[i][2] * t[2]);
  }
  out[15] = 1;
  return out;
}
function perspective(fovY, aspect, near, far) {
  const f = 1 / Math.tan(fovY / 2);
  return new Float32Array([f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) / (near - far), -1,
    0, 0, (2 * far * near) / (near - far), 0]);
}
function translation(p) {
  return new Float32Array([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, p[0], p[1], p[2], 1]);
}

class EmulatedTransform {
  constructor(matrix) {
    this.matrix = matrix;
    this.position = { x: matrix[12], y: matrix[13], z: matrix[14], w: 1 };
    this.orientation = { x: 0, y: 0, z: 0, w: 1 };  // the head's is not read by three.js
  }
  get inverse() { return new EmulatedTransform(invertRigid(this.matrix)); }
}

class EmulatedLayer {
  constructor(session, gl) {
    this.context = gl;
    this.framebuffer = null;  // the canvas itself
    this.framebufferWidth = gl.drawingBufferWidth;
    this.framebufferHeight = gl.drawingBufferHeight;
    this.ignoreDepthValues = false;
    this.antialias = true;
  }
  getViewport() {
    return { x: 0, y: 0, width: this.framebufferWidth, height: this.framebufferHeight };
  }
}

class EmulatedFrame {
  constructor(session, timeS) {
    this.session = session;
    this.joints = { right: handJoints(timeS, "right"), left: handJoints(timeS, "left") };
  }
  getViewerPose() {
    const layer = this.session.renderState.baseLayer;
    const aspect = layer ? layer.framebufferWidth / layer.framebufferHeight : 1;
    const transform = new EmulatedTransform(lookAtMatrix(HEAD_XR_M, LOOK_AT_XR_M));
    return {
      transform,
      emulatedPosition: false,
      views: [{ eye: "none", transform, projectionMatrix: perspective(FOV_Y_RAD, aspect, 0.01, 50) }],
    };
  }
  getPose() { return null; }
  getJointPose(jointSpace) {
    const p = this.joints[jointSpace.side][jointSpace.jointName];
    if (!p) return null;
    return { transform: new EmulatedTransform(translation(p)), radius: 0.008, emulatedPosition: false };
  }
}

class EmulatedSession extends EventTarget {
  constructor(mode) {
    super();
    this.mode = mode;
    this.renderState = { baseLayer: null, depthNear: 0.1, depthFar: 1000 };
    this.environmentBlendMode = mode === "immersive-ar" ? "alpha-blend" : "opaque";
    this.enabledFeatures = ["local-floor", "hand-tracking"];
    this.visibilityState = "visible";
    this.supportedFrameRates = new Float32Array([72, 90]);
    this.frameRate = 90;
    const source = (side) => ({
      handedness: side,
      hand: new Map(JOINTS.map((name) => [name, { jointName: name, side }])),
      targetRayMode: "tracked-pointer", profiles: ["generic-hand"], gamepad: null,
      gripSpace: {}, targetRaySpace: {} });
    this.inputSources = TWO_HANDS ? [source("right"), source("left")] : [source("right")];
    this.ended = false;
    this.startMs = performance.now();
    window.handsimXrTest.session = this;
  }
  updateRenderState(state) { Object.assign(this.renderState, state); }
  async requestReferenceSpace(type) {
    const space = { type, getOffsetReferenceSpace: () => space, addEventListener() {} };
    return space;
  }
  requestAnimationFrame(callback) {
    return window.requestAnimationFrame((t) => {
      if (this.ended) return;
      window.handsimXrTest.frames += 1;
      callback(t, new EmulatedFrame(this, (t - this.startMs) / 1000));
    });
  }
  cancelAnimationFrame(id) { window.cancelAnimationFrame(id); }
  async updateTargetFrameRate(rate) { this.frameRate = rate; }
  async end() {
    this.ended = true;
    this.dispatchEvent(new Event("end"));
  }
}

window.handsimXrTest = { frames: 0, session: null };
const device = {
  async isSessionSupported(mode) { return mode === "immersive-vr" || mode === "immersive-ar"; },
  async requestSession(mode) { return new EmulatedSession(mode); },
  addEventListener() {},
  removeEventListener() {},
};
Object.defineProperty(navigator, "xr", { value: device, configurable: true });
window.XRWebGLLayer = EmulatedLayer;
// The emulated device has no WebXR Layers: three.js then uses the XRWebGLLayer path.
window.XRWebGLBinding = undefined;
for (const ctx of [window.WebGLRenderingContext, window.WebGL2RenderingContext]) {
  if (ctx) ctx.prototype.makeXRCompatible = async function makeXRCompatible() {};
}
