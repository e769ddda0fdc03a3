// volgen view: draws the server's scenes by ray marching them as a 3D texture in WebGL2, with
// volrender's model (docs/volrender.md): uniform midpoint samples between the ray's box entry
// and exit, cell-centred trilinear interpolation (edge-clamped inside the box, zero outside),
// density activated per sample where the model post-activates it, and the model's background.
// Plain WebGL2, no library: the page loads nothing but this server's own files.
"use strict";

// A ray stops once its transmittance is at most this: its colour then moves by at most this
// much (volrender's bound, docs/volrender.md), a quarter of one 8-bit level.
const EPSILON = 1e-3;

const VERTEX_SHADER = `#version 300 es
// One triangle that covers the canvas.
void main() {
  vec2 corner = vec2(float((gl_VertexID & 1) * 4 - 1), float((gl_VertexID & 2) * 2 - 1));
  gl_Position = vec4(corner, 0.0, 1.0);
}`;

const FRAGMENT_SHADER = `#version 300 es
precision highp float;
precision highp int;
precision highp sampler3D;

// (D, H, W) texels of density (raw when post-activated) and colour, fetched without filtering:
// the interpolation below is volgen's, in 32-bit floats.
uniform sampler3D volume;
uniform ivec3 dims;            // cells along x, y, z
uniform vec3 boxMin;
uniform vec3 boxMax;
uniform mat4 c2w;              // camera to world: looks down -Z, +Y up (NeRF, Blender)
uniform vec4 intrinsics;       // fx, fy, cx, cy in pixels
uniform float height;          // pixels
uniform int samples;
uniform bool postActivated;
uniform vec2 activation;       // sigma = scale * softplus(raw + shift)
uniform vec3 background;
uniform float epsilon;
out vec4 colour;

float softplus(float x) {
  return max(x, 0.0) + log(1.0 + exp(-abs(x)));
}

vec4 texel(ivec3 i) {
  return texelFetch(volume, i, 0);
}

void main() {
  // Pixel (row, col) has its centre at (row + 0.5, col + 0.5), rows counted from the top.
  float col = gl_FragCoord.x;
  float row = height - gl_FragCoord.y;
  vec3 towards = vec3((col - intrinsics.z) / intrinsics.x, -(row - intrinsics.w) / intrinsics.y, -1.0);
  vec3 d = normalize(mat3(c2w) * towards);
  vec3 o = c2w[3].xyz;

  // The ray's entry and exit of the box (volrender's slab test); rays from inside start at 0.
  float tNear = -1e30;
  float tFar = 1e30;
  bool hit = true;
  for (int a = 0; a < 3; a++) {
    if (d[a] == 0.0) {
      hit = hit && o[a] >= boxMin[a] && o[a] <= boxMax[a];
    } else {
      float ta = (boxMin[a] - o[a]) / d[a];
      float tb = (boxMax[a] - o[a]) / d[a];
      tNear = max(tNear, min(ta, tb));
      tFar = min(tFar, max(ta, tb));
    }
  }
  float t0 = max(tNear, 0.0);
  if (!hit || !(tFar > t0)) {
    colour = vec4(background, 1.0);
    return;
  }
  float dt = (tFar - t0) / float(samples);

  // Index space: cell i's centre at u = i.
  vec3 cells = vec3(dims);
  vec3 voxel = (boxMax - boxMin) / cells;
  vec3 start = (o - boxMin) / voxel - 0.5;
  vec3 step = d / voxel;
  ivec3 last = dims - 1;

  float transmittance = 1.0;
  vec3 rgb = vec3(0.0);
  for (int i = 0; i < samples; i++) {
    vec3 u = start + (t0 + (float(i) + 0.5) * dt) * step;
    if (any(lessThan(u, vec3(-0.5))) || any(greaterThan(u, cells - 0.5))) {
      continue; // outside the box: nothing there
    }
    vec3 uc = clamp(u, vec3(0.0), vec3(last)); // beyond the outermost centres: the edge value
    ivec3 i0 = ivec3(uc);
    ivec3 i1 = min(i0 + 1, last);
    vec3 f = uc - vec3(i0);
    vec4 x00 = mix(texel(i0), texel(ivec3(i1.x, i0.y, i0.z)), f.x);
    vec4 x10 = mix(texel(ivec3(i0.x, i1.y, i0.z)), texel(ivec3(i1.x, i1.y, i0.z)), f.x);
    vec4 x01 = mix(texel(ivec3(i0.x, i0.y, i1.z)), texel(ivec3(i1.x, i0.y, i1.z)), f.x);
    vec4 x11 = mix(texel(ivec3(i0.x, i1.y, i1.z)), texel(i1), f.x);
    vec4 value = mix(mix(x00, x10, f.y), mix(x01, x11, f.y), f.z);
    float sigma = postActivated ? activation.x * softplus(value.r + activation.y) : value.r;
    float tau = sigma * dt;
    float keep = exp(-tau);
    // 1 - exp(-tau) loses its digits for small tau: a series there, as volrender does.
    float alpha = tau < 1e-3 ? tau * (1.0 - tau * (0.5 - tau / 6.0)) : 1.0 - keep;
    rgb += transmittance * alpha * value.gba;
    transmittance *= keep;
    if (transmittance <= epsilon) {
      break;
    }
  }
  colour = vec4(rgb + transmittance * background, 1.0);
}`;

const $ = (id) => document.getElementById(id);

// What the page shows and what it was asked for.
const state = {
  info: null,
  scene: null,       // the drawn scene's description (server JSON)
  want: { seed: "0", vary: 1, walk: 0, extent: "1,1,1", outside: "mirror", file: 0 },
  loading: false,
  reload: false,
  frames: 0,         // frames drawn so far
  epsilon: EPSILON,
};

// The camera: an orbit about the scene's centre, or a training view's camera until the next
// drag or zoom.
const camera = {
  azimuth: 0,
  elevation: 0,
  radius: 1,
  fovX: 0.6,
  centre: [0, 0, 0],
  view: null,        // index of the training view whose camera is used
};

// ---------------------------------------------------------------------------------------
// Vectors and the camera's matrix, as volrender's Camera::look_at makes it.

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const length = (a) => Math.hypot(a[0], a[1], a[2]);
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];

function eye() {
  const { azimuth: az, elevation: el, radius: r, centre: c } = camera;
  return [
    c[0] + r * Math.cos(el) * Math.cos(az),
    c[1] + r * Math.cos(el) * Math.sin(az),
    c[2] + r * Math.sin(el),
  ];
}

// Camera-to-world, column-major: right, up, back, position.
function lookAt(from, to) {
  const ahead = sub(to, from);
  const forward = scale(ahead, 1 / length(ahead));
  let right = null;
  for (const up of [[0, 0, 1], [0, 1, 0], [1, 0, 0]]) {
    const r = cross(forward, up);
    if (length(r) > 1e-6) {
      right = scale(r, 1 / length(r));
      break;
    }
  }
  const up = cross(right, forward);
  return [...right, 0, ...up, 0, ...scale(forward, -1), 0, ...from, 1];
}

// The camera drawn now: c2w (column-major) and intrinsics in pixels of the canvas.
function currentCamera() {
  const canvas = $("scene");
  const [w, h] = [canvas.width, canvas.height];
  if (camera.view !== null) {
    const v = state.info.views[camera.view];
    return {
      c2w: v.c2w,
      fx: (v.fx * w) / v.width,
      fy: (v.fy * h) / v.height,
      cx: (v.cx * w) / v.width,
      cy: (v.cy * h) / v.height,
      width: w,
      height: h,
    };
  }
  const f = (0.5 * w) / Math.tan(0.5 * camera.fovX);
  return { c2w: lookAt(eye(), camera.centre), fx: f, fy: f, cx: 0.5 * w, cy: 0.5 * h, width: w, height: h };
}

// Leaves a training view's camera for the orbit through the same eye.
function orbitFromView() {
  if (camera.view === null) return;
  const cam = currentCamera();
  const position = cam.c2w.slice(12, 15);
  const offset = sub(position, camera.centre);
  camera.radius = length(offset);
  camera.elevation = Math.asin(Math.max(-1, Math.min(1, offset[2] / camera.radius)));
  camera.azimuth = Math.atan2(offset[1], offset[0]);
  camera.fovX = 2 * Math.atan((0.5 * cam.width) / cam.fx);
  selectView(null);
}

// The default view of a scene of box `box`: volgen sample's showcase camera, as far out as
// the box needs.
function defaultRadius(box) {
  const half = Math.max(box[3] - box[0], box[4] - box[1], box[5] - box[2]) / 2;
  return state.info.camera.radius * Math.max(state.info.camera.half, half);
}

function resetCamera() {
  const c = state.info.camera;
  camera.azimuth = c.azimuth;
  camera.elevation = c.elevation;
  camera.fovX = c.fov_x;
  camera.centre = state.scene ? boxCentre(state.scene.box) : c.centre;
  camera.radius = state.scene ? defaultRadius(state.scene.box) : c.radius * c.half;
  selectView(null);
  requestDraw();
}

const boxCentre = (b) => [(b[0] + b[3]) / 2, (b[1] + b[4]) / 2, (b[2] + b[5]) / 2];

// ---------------------------------------------------------------------------------------
// WebGL2.

let gl = null;
let program = null;
let uniforms = {};
let texture = null;

function compile(type, source) {
  const shader = gl.createShader(type);
  gl.shaderSource(shader, source);
  gl.compileShader(shader);
  if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS)) {
    throw new Error("shader: " + gl.getShaderInfoLog(shader));
  }
  return shader;
}

function setUpGl() {
  gl = $("scene").getContext("webgl2", { antialias: false, alpha: false, depth: false });
  if (!gl) throw new Error("this browser has no WebGL2");
  program = gl.createProgram();
  gl.attachShader(program, compile(gl.VERTEX_SHADER, VERTEX_SHADER));
  gl.attachShader(program, compile(gl.FRAGMENT_SHADER, FRAGMENT_SHADER));
  gl.linkProgram(program);
  if (!gl.getProgramParameter(program, gl.LINK_STATUS)) {
    throw new Error("shader: " + gl.getProgramInfoLog(program));
  }
  for (const name of ["volume", "dims", "boxMin", "boxMax", "c2w", "intrinsics", "height", "samples",
                      "postActivated", "activation", "background", "epsilon"]) {
    uniforms[name] = gl.getUniformLocation(program, name);
  }
  gl.bindVertexArray(gl.createVertexArray());
  texture = gl.createTexture();
}

// Uploads a scene's texture: RGBA 32-bit floats, x fastest, fetched texel by texel.
function upload(scene, buffer) {
  const [w, h, d] = scene.dims;
  const most = gl.getParameter(gl.MAX_3D_TEXTURE_SIZE);
  if (Math.max(w, h, d) > most) {
    throw new Error(`the scene's ${w} x ${h} x ${d} grid exceeds this GPU's 3D textures (${most} per side)`);
  }
  gl.bindTexture(gl.TEXTURE_3D, texture);
  gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
  gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
  gl.pixelStorei(gl.UNPACK_ALIGNMENT, 4);
  gl.texImage3D(gl.TEXTURE_3D, 0, gl.RGBA32F, w, h, d, 0, gl.RGBA, gl.FLOAT, new Float32Array(buffer));
}

function drawFrame() {
  const scene = state.scene;
  if (!scene) return;
  const cam = currentCamera();
  gl.viewport(0, 0, cam.width, cam.height);
  gl.useProgram(program);
  gl.activeTexture(gl.TEXTURE0);
  gl.bindTexture(gl.TEXTURE_3D, texture);
  gl.uniform1i(uniforms.volume, 0);
  gl.uniform3i(uniforms.dims, ...scene.dims);
  gl.uniform3f(uniforms.boxMin, ...scene.box.slice(0, 3));
  gl.uniform3f(uniforms.boxMax, ...scene.box.slice(3, 6));
  gl.uniformMatrix4fv(uniforms.c2w, false, cam.c2w);
  gl.uniform4f(uniforms.intrinsics, cam.fx, cam.fy, cam.cx, cam.cy);
  gl.uniform1f(uniforms.height, cam.height);
  gl.uniform1i(uniforms.samples, scene.samples);
  const post = scene.density.rule === "post-activated";
  gl.uniform1i(uniforms.postActivated, post ? 1 : 0);
  gl.uniform2f(uniforms.activation, post ? scene.density.scale : 1, post ? scene.density.shift : 0);
  gl.uniform3f(uniforms.background, ...scene.background);
  gl.uniform1f(uniforms.epsilon, state.epsilon);
  gl.drawArrays(gl.TRIANGLES, 0, 3);
  state.frames += 1;
}

let drawPending = false;
function requestDraw() {
  if (drawPending) return;
  drawPending = true;
  requestAnimationFrame(() => {
    drawPending = false;
    drawFrame();
  });
}

// ---------------------------------------------------------------------------------------
// Scenes from the server: one request at a time; the newest wish wins.

function sceneQuery(want) {
  const q = new URLSearchParams();
  if (state.info.kind === "files") {
    q.set("file", want.file);
  } else {
    q.set("seed", want.seed);
    q.set("vary", want.vary);
    q.set("walk", want.walk);
    q.set("extent", want.extent);
    q.set("outside", want.outside);
  }
  return q.toString();
}

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

async function load() {
  if (state.loading) {
    state.reload = true;
    return;
  }
  state.loading = true;
  try {
    do {
      state.reload = false;
      const response = await fetch("/api/scene?" + sceneQuery(state.want));
      if (response.status === 503) {
        // The generator is busy with others' requests: ask again shortly.
        await sleep(300);
        state.reload = true;
        continue;
      }
      if (!response.ok) {
        showError((await response.text()).trim());
        continue;
      }
      const scene = await response.json();
      const volume = await fetch(scene.volume);
      if (!volume.ok) {
        state.reload = true; // dropped from the server's cache meanwhile
        continue;
      }
      const buffer = await volume.arrayBuffer();
      const resized = !state.scene || state.scene.box.some((v, i) => v !== scene.box[i]);
      upload(scene, buffer);
      state.scene = scene;
      if (resized) resetCamera();
      showScene(scene);
      requestDraw();
    } while (state.reload);
  } catch (e) {
    showError(String(e.message || e));
  } finally {
    state.loading = false;
  }
}

function showError(message) {
  const status = $("status");
  status.textContent = message;
  status.classList.add("error");
}

function showScene(scene) {
  const status = $("status");
  status.classList.remove("error");
  const [w, h, d] = scene.dims;
  const what = scene.seed !== undefined
    ? `seed ${scene.seed} · vary from ${scene.vary} · walk ${scene.walk} · extent ${scene.extent}` +
      (scene.extent === "1,1,1" ? "" : ` (${scene.outside})`) +
      ` · drawn in ${scene.seconds.toFixed(3)} s`
    : scene.name;
  status.textContent = `${what} · ${w}×${h}×${d} voxels · ${scene.samples} samples per ray, ` +
    `${scene.density.rule} density`;
  for (const format of ["safetensors", "vdb", "glb"]) {
    const link = $("download-" + format);
    link.href = scene.downloads[format];
    link.download = scene.name + "." + format;
  }
}

function ask(change) {
  Object.assign(state.want, change);
  load();
}

// ---------------------------------------------------------------------------------------
// Controls.

function setUpControls(info) {
  $("title").textContent = info.title;
  const model = info.kind === "model";
  for (const el of document.querySelectorAll(model ? ".files-only" : ".model-only")) {
    el.classList.add("hidden");
  }
  if (model) {
    const vary = $("vary");
    for (let n = 1; n <= info.scales; n++) {
      vary.add(new Option(n === 1 ? "1 (everything varies)" : String(n), String(n)));
    }
    vary.addEventListener("change", () => ask({ vary: Number(vary.value) }));
    const seed = $("seed");
    seed.addEventListener("change", () => ask({ seed: seed.value.trim() }));
    $("new-scene").addEventListener("click", () => {
      const fresh = String(crypto.getRandomValues(new Uint32Array(1))[0]);
      seed.value = fresh;
      ask({ seed: fresh });
    });
    const walk = $("walk");
    walk.max = String(info.walk_max);
    walk.disabled = info.walk_max === 0;
    walk.addEventListener("input", () => {
      $("walk-frame").value = walk.value;
      ask({ walk: Number(walk.value) });
    });
    const choices = $("extent-choices");
    for (const choice of info.extent.choices) choices.append(new Option(choice));
    const extent = $("extent");
    extent.addEventListener("change", () => ask({ extent: extent.value.trim() }));
    const outside = $("outside");
    for (const name of info.extent.outside) outside.add(new Option(name));
    outside.value = state.want.outside;
    outside.addEventListener("change", () => ask({ outside: outside.value }));
  } else {
    const file = $("file");
    info.files.forEach((name, i) => file.add(new Option(name, String(i))));
    file.addEventListener("change", () => ask({ file: Number(file.value) }));
  }
  $("reset-camera").addEventListener("click", resetCamera);
  $("download-camera").addEventListener("click", downloadCamera);
  setUpViews(info.views);
}

// The camera as a transforms.json that volgen render reads (--cameras view.json --width W
// --height H).
function downloadCamera(event) {
  const cam = currentCamera();
  const m = cam.c2w;
  const rows = [0, 1, 2, 3].map((r) => [m[r], m[4 + r], m[8 + r], m[12 + r]]);
  const transforms = {
    fl_x: cam.fx, fl_y: cam.fy, cx: cam.cx, cy: cam.cy, w: cam.width, h: cam.height,
    frames: [{ file_path: "view", transform_matrix: rows }],
  };
  const blob = new Blob([JSON.stringify(transforms, null, 1)], { type: "application/json" });
  event.currentTarget.href = URL.createObjectURL(blob);
}

function setUpViews(views) {
  if (!views.length) return;
  $("strip").hidden = false;
  const strip = $("views");
  views.forEach((view, i) => {
    const button = document.createElement("button");
    button.setAttribute("aria-pressed", "false");
    button.title = `training view ${i}`;
    const image = new Image(72, 72);
    image.loading = "lazy";
    image.src = view.image;
    image.alt = `training view ${i}`;
    button.append(image);
    button.addEventListener("click", () => selectView(i));
    strip.append(button);
  });
}

// Shows training view `i` beside the scene drawn from its camera (null: none).
function selectView(i) {
  camera.view = i;
  const buttons = $("views").children;
  for (let b = 0; b < buttons.length; b++) {
    buttons[b].setAttribute("aria-pressed", String(b === i));
  }
  const figure = $("training");
  figure.hidden = i === null;
  if (i !== null) {
    $("training-image").src = state.info.views[i].image;
    $("training-caption").textContent = `training view ${i}; left: the scene from its camera`;
  }
  requestDraw();
}

// Orbit by dragging (mouse, pen or one finger), zoom by wheel or pinch.
function setUpPointer() {
  const canvas = $("scene");
  const pointers = new Map();
  const spread = () => {
    const [a, b] = [...pointers.values()];
    return Math.hypot(a.x - b.x, a.y - b.y);
  };
  const zoom = (factor) => {
    orbitFromView();
    const base = state.scene ? defaultRadius(state.scene.box) : camera.radius;
    camera.radius = Math.min(8 * base, Math.max(0.1 * base, camera.radius * factor));
    requestDraw();
  };
  canvas.addEventListener("pointerdown", (e) => {
    canvas.setPointerCapture(e.pointerId);
    pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
  });
  canvas.addEventListener("pointermove", (e) => {
    const last = pointers.get(e.pointerId);
    if (!last) return;
    if (pointers.size === 1) {
      orbitFromView();
      camera.azimuth -= (e.clientX - last.x) * 0.01;
      camera.elevation = Math.max(-1.5, Math.min(1.5, camera.elevation + (e.clientY - last.y) * 0.01));
      requestDraw();
      pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
    } else if (pointers.size === 2) {
      const before = spread();
      pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
      if (before > 0 && spread() > 0) zoom(before / spread());
    }
  });
  const release = (e) => pointers.delete(e.pointerId);
  canvas.addEventListener("pointerup", release);
  canvas.addEventListener("pointercancel", release);
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    zoom(Math.exp(e.deltaY * 0.0015));
  }, { passive: false });
}

// ---------------------------------------------------------------------------------------
// For tests and measurements (the browser check drives the page through these).

window.volgen = {
  // Whether the page has drawn a scene and waits for nothing.
  idle: () => state.scene !== null && !state.loading && !drawPending,
  scene: () => state.scene,
  camera: currentCamera,
  frames: () => state.frames,
  setEpsilon: (e) => {
    state.epsilon = e;
    requestDraw();
  },
  // Mean milliseconds per frame over `frames` frames, each waited for (a 1-pixel read).
  benchmark: (frames = 60) => {
    const pixel = new Uint8Array(4);
    drawFrame();
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);
    const start = performance.now();
    for (let i = 0; i < frames; i++) {
      drawFrame();
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);
    }
    return (performance.now() - start) / frames;
  },
};

async function main() {
  try {
    setUpGl();
    const response = await fetch("/api/info");
    state.info = await response.json();
    setUpControls(state.info);
    setUpPointer();
    resetCamera();
    await load();
  } catch (e) {
    showError(String(e.message || e));
  }
}

main();
