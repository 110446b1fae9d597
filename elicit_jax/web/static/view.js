// The 3-D view: a three.js scene built once from the server's geom description, posed by
// streamed body poses. Z is up (MuJoCo's convention). Depth cues: shadows on the floor (with
// software WebGL, where a shadow map costs a pass per frame: a soft dark disc under each
// moving body) and a top-down inset in the corner. A split mode shows two copies of the scene side by side (an
// operator's window beside the retrieved base segment), each with its top view and the two
// gripper paths (trails). Renders only when something changed; streamed poses glide from the
// pose shown to the new one over a frame period (no jumps when frames come in bursts), and the
// Player replays clips against the clock, between steps too.
import * as THREE from './three/three.module.js';
import { OrbitControls } from './three/OrbitControls.js';

const SOFTWARE_PIXELS = 160000;
const SOFTWARE_MIN_PIXELS = 40000;
const SLOW_MS = 60;  // a moving view drawn less often than this (17 frames/s) draws fewer pixels
const FAST_MS = 40;  // and more often than this (25 frames/s) more
const SOFTWARE_FPS = 30;
const HOME = { position: new THREE.Vector3(-0.5, -0.2, 0.5), target: new THREE.Vector3(0.03, 0.0, 0.03) };

function geometryOf(item) {
  const [a, b, c] = item.size;
  let g;
  switch (item.type) {
    case 'box': g = new THREE.BoxGeometry(2 * a, 2 * b, 2 * c); break;
    case 'sphere': g = new THREE.SphereGeometry(a, 24, 16); break;
    case 'ellipsoid': g = new THREE.SphereGeometry(1, 24, 16); g.scale(a, b, c); break;
    case 'capsule': g = new THREE.CapsuleGeometry(a, 2 * b, 8, 24); g.rotateX(Math.PI / 2); break;
    case 'cylinder': g = new THREE.CylinderGeometry(a, a, 2 * b, 32); g.rotateX(Math.PI / 2); break;
    case 'plane': g = new THREE.PlaneGeometry(2 * (a || 2.5), 2 * (b || 2.5)); break;
    default: return null;
  }
  return g;
}

// A software WebGL (SwiftShader, llvmpipe: no GPU) is slow at multisampling: skip it there.
function softwareRenderer() {
  try {
    const gl = document.createElement('canvas').getContext('webgl2');
    const ext = gl && gl.getExtension('WEBGL_debug_renderer_info');
    const name = ext ? String(gl.getParameter(ext.UNMASKED_RENDERER_WEBGL)) : '';
    const lose = gl && gl.getExtension('WEBGL_lose_context');
    if (lose) lose.loseContext();
    return /swiftshader|llvmpipe|software/i.test(name);
  } catch (e) {
    return false;
  }
}

function buildInstance(desc, shadowSize, lite) {
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xeef1f5);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8f99, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 2.2);
  sun.position.set(-0.3, -0.4, 1.2);
  sun.target.position.set(0, 0, 0);
  sun.castShadow = !lite;
  sun.shadow.mapSize.set(shadowSize, shadowSize);
  Object.assign(sun.shadow.camera, { left: -0.5, right: 0.5, top: 0.5, bottom: -0.5, near: 0.1, far: 3 });
  sun.shadow.bias = -0.0005;
  scene.add(sun, sun.target);
  const grid = new THREE.GridHelper(1.0, 20, 0xb0b4ba, 0xcfd3d8);
  grid.rotateX(Math.PI / 2);
  grid.position.z = 0.0005;
  scene.add(grid);
  const bodies = desc.bodies.map((name) => {
    const g = new THREE.Group();
    g.name = name;
    scene.add(g);
    return g;
  });
  for (const item of desc.items) {
    const geom = geometryOf(item);
    if (!geom) continue;
    const [r, g, b, alpha] = item.rgba;
    const color = new THREE.Color(r, g, b);
    const mat = lite
      ? new THREE.MeshLambertMaterial({ color, transparent: alpha < 1, opacity: alpha })
      : item.type === 'plane'
        ? new THREE.MeshStandardMaterial({ color, roughness: 1 })
        : new THREE.MeshStandardMaterial({
          color, roughness: 0.6, metalness: 0.05, transparent: alpha < 1, opacity: alpha,
        });
    const mesh = new THREE.Mesh(geom, mat);
    mesh.name = item.name;
    mesh.position.set(...item.pos);
    mesh.quaternion.set(item.quat[1], item.quat[2], item.quat[3], item.quat[0]);
    mesh.castShadow = !lite && item.type !== 'plane' && alpha >= 1;
    mesh.receiveShadow = !lite;
    bodies[item.body].add(mesh);
  }
  // lite: a soft disc on the floor under each body that moves (its x, y follow the body)
  const blobs = !lite ? [] : bodies.map((body, i) => {
    if (i === 0 || !desc.items.some((it) => it.body === i && it.type !== 'plane')) return null;
    const disc = new THREE.Mesh(new THREE.CircleGeometry(0.025, 20),
      new THREE.MeshBasicMaterial({ color: 0x000000, transparent: true, opacity: 0.25, depthWrite: false }));
    disc.position.z = 0.001;
    scene.add(disc);
    return disc;
  });
  const trails = [0xe8590c, 0x1c7ed6].map((color) => {
    const line = new THREE.Line(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color, linewidth: 2 }));
    line.frustumCulled = false;
    line.visible = false;
    scene.add(line);
    return line;
  });
  return { scene, bodies, blobs, trails, shown: null, from: null, to: null, t0: 0, glide: 0, buf: null };
}

// Blend poses a -> b (nbody * 7: x, y, z, qw, qx, qy, qz) by t in [0, 1] into out: positions
// linearly, rotations by normalised lerp on the shorter arc.
export function blendPoses(a, b, t, out) {
  for (let o = 0; o < b.length; o += 7) {
    for (let k = 0; k < 3; k++) out[o + k] = a[o + k] + (b[o + k] - a[o + k]) * t;
    const dot = a[o + 3] * b[o + 3] + a[o + 4] * b[o + 4] + a[o + 5] * b[o + 5] + a[o + 6] * b[o + 6];
    const s = dot < 0 ? -1 : 1;
    let n = 0;
    for (let k = 3; k < 7; k++) { out[o + k] = a[o + k] + (s * b[o + k] - a[o + k]) * t; n += out[o + k] ** 2; }
    n = Math.sqrt(n) || 1;
    for (let k = 3; k < 7; k++) out[o + k] /= n;
  }
  return out;
}

export class View {
  constructor(container) {
    this.container = container;
    // Software WebGL (no GPU): no multisampling, and at most this.budget pixels drawn per
    // frame, or drawing stalls the page (setFullQuality(true) lifts the cap, e.g. for a
    // screenshot).
    this.software = softwareRenderer();
    this.fullQuality = false;
    this.renderer = new THREE.WebGLRenderer({ antialias: !this.software });
    this.renderer.shadowMap.enabled = !this.software;
    this.renderer.shadowMap.type = THREE.PCFShadowMap;
    this.renderer.setScissorTest(true);
    container.appendChild(this.renderer.domElement);
    this.camera = new THREE.PerspectiveCamera(45, 1, 0.01, 20);
    this.camera.up.set(0, 0, 1);
    this.camera.position.copy(HOME.position);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.target.copy(HOME.target);
    this.controls.update();
    this.controls.addEventListener('change', () => this.dirty());
    this.top = new THREE.OrthographicCamera(-0.3, 0.3, 0.3, -0.3, 0.01, 5);
    this.top.up.set(1, 0, 0);
    this.top.position.set(0, 0, 2);
    this.top.lookAt(0, 0, 0);
    this.instances = [];
    this.names = [];
    this.split = false;
    this.labels = ['', ''];
    this._dirty = true;
    this.rendered = 0;
    new ResizeObserver(() => this.dirty()).observe(container);
    // Software WebGL costs ~30 ms of CPU a frame whatever the scene: at most SOFTWARE_FPS
    // frames a second there, leaving the rest of the CPU to the page and the server.
    this.minGap = this.software ? 1000 / SOFTWARE_FPS - 2 : 0;
    let lastDraw = 0, wasMoving = false;
    this.budget = SOFTWARE_PIXELS;
    this.gaps = [];
    const loop = (now) => {
      if (now - lastDraw >= this.minGap) {
        const moving = this.instances.some((inst) => inst.from);
        this.glide(now);
        if (this._dirty) {
          this.render();
          if (moving && wasMoving && this.software) this.adapt(now - lastDraw);
          wasMoving = moving;
          lastDraw = now;
        }
      }
      requestAnimationFrame(loop);
    };
    requestAnimationFrame(loop);
  }

  build(desc) {
    this.desc = desc;
    this.names = desc.bodies;
    const home = desc.home;  // a task may say where the camera starts (robosuite's scenes)
    this.home = home ? { position: new THREE.Vector3(...home.position), target: new THREE.Vector3(...home.target) } : HOME;
    if (home && !this.homed) { this.homed = true; this.resetCamera(); }
    const lite = this.software && !this.fullQuality;
    const shown = this.instances.map((inst) => inst.shown);
    this.renderer.shadowMap.enabled = !lite;
    this.instances = [0, 1].map(() => buildInstance(desc, lite ? 512 : 2048, lite));
    shown.forEach((poses, i) => { if (poses && this.instances[i]) this.apply(this.instances[i], poses); });
    if (this.trailPaths) this.setTrails(this.trailPaths);
    this.dirty();
  }

  resetCamera() {
    const home = this.home || HOME;
    this.camera.position.copy(home.position);
    this.controls.target.copy(home.target);
    this.controls.update();
    this.dirty();
  }

  dirty() { this._dirty = true; }

  // Software WebGL: the pixel budget follows how often a moving view gets drawn (each frame
  // costs CPU in proportion to its pixels, on top of a fixed part), between
  // SOFTWARE_MIN_PIXELS and SOFTWARE_PIXELS, so a busy machine still shows motion smoothly.
  adapt(gap) {
    this.gaps.push(gap);
    if (this.gaps.length < 15) return;
    const median = this.gaps.sort((a, b) => a - b)[7];
    this.gaps = [];
    const budget = median > SLOW_MS ? this.budget * 0.7 : median < FAST_MS ? this.budget * 1.25 : this.budget;
    const next = Math.round(Math.max(SOFTWARE_MIN_PIXELS, Math.min(SOFTWARE_PIXELS, budget)));
    if (next !== this.budget) { this.budget = next; this.size = ''; }
  }

  // Full quality lifts the software limits (pixels, shadows, materials), e.g. for a screenshot.
  setFullQuality(on) {
    this.fullQuality = on;
    this.size = '';
    if (this.software && this.desc) this.build(this.desc);
    this.render();
  }

  // poses: Float32Array of nbody * 7 (x, y, z, qw, qx, qy, qz), into instance i; glide > 0:
  // move there from the pose shown over glide ms (streamed frames), else at once.
  pose(poses, i = 0, glide = 0) {
    const inst = this.instances[i];
    if (i === 0) this.last = poses;
    if (!inst) return;
    if (glide > 0 && inst.shown && inst.shown.length === poses.length) {
      inst.from = Float32Array.from(inst.shown);
      inst.to = poses;
      inst.t0 = performance.now();
      inst.glide = glide;
      this.glide(inst.t0);
    } else {
      inst.from = null;
      this.apply(inst, poses);
    }
  }

  // Advance the gliding instances to time now (the animation loop calls it every frame).
  glide(now) {
    for (const inst of this.instances) {
      if (!inst.from) continue;
      const t = Math.min(1, Math.max(0, (now - inst.t0) / inst.glide));
      if (!inst.buf || inst.buf.length !== inst.to.length) inst.buf = new Float32Array(inst.to.length);
      this.apply(inst, t >= 1 ? inst.to : blendPoses(inst.from, inst.to, t, inst.buf));
      if (t >= 1) inst.from = null;
    }
  }

  apply(inst, poses) {
    const same = inst.shown && inst.shown.length === poses.length && inst.shown.every((v, k) => v === poses[k]);
    if (same) return;  // nothing moved: nothing to draw
    const n = Math.min(inst.bodies.length, poses.length / 7);
    for (let b = 0; b < n; b++) {
      const o = b * 7;
      inst.bodies[b].position.set(poses[o], poses[o + 1], poses[o + 2]);
      inst.bodies[b].quaternion.set(poses[o + 4], poses[o + 5], poses[o + 6], poses[o + 3]);
      if (inst.blobs[b]) inst.blobs[b].position.set(poses[o], poses[o + 1], 0.001);
    }
    inst.shown = Float32Array.from(poses);
    this.dirty();
  }

  // Gripper paths drawn in every instance: paths[0] orange (yours), paths[1] blue (base); each
  // an array of [x, y, z] or null.
  setTrails(paths) {
    this.trailPaths = paths;
    for (const inst of this.instances) {
      inst.trails.forEach((line, k) => {
        const pts = paths && paths[k];
        line.visible = Boolean(pts && pts.length > 1);
        if (line.visible) line.geometry.setFromPoints(pts.map((p) => new THREE.Vector3(p[0], p[1], p[2] + 0.001)));
      });
    }
    this.dirty();
  }

  // The position body `name` is drawn at in instance i (gliding included).
  shownPosition(name, i = 0) {
    const b = this.names.indexOf(name), inst = this.instances[i];
    if (b < 0 || !inst || !inst.shown) return null;
    return Array.from(inst.shown.slice(b * 7, b * 7 + 3));
  }

  bodyPosition(name) {
    const b = this.names.indexOf(name);
    if (b < 0 || !this.last) return null;
    return Array.from(this.last.slice(b * 7, b * 7 + 3));
  }

  setSplit(on, labels = ['', '']) {
    this.split = on;
    this.labels = labels;
    this.dirty();
  }

  render() {
    this._dirty = false;
    this.rendered += 1;
    const w = this.container.clientWidth, h = this.container.clientHeight;
    if (!w || !h || !this.instances.length) return;
    const r = this.renderer;
    if (this.size !== `${w}x${h}`) {
      this.size = `${w}x${h}`;
      const ratio = this.software && !this.fullQuality
        ? Math.min(1, Math.sqrt(this.budget / (w * h)))
        : Math.min(window.devicePixelRatio || 1, 2);
      r.setPixelRatio(ratio);
      r.setSize(w, h, false);
    }
    if (this.split) {
      const half = Math.floor(w / 2);
      this.camera.aspect = half / h;
      this.camera.updateProjectionMatrix();
      const s = Math.floor(Math.min(half, h) * 0.3);
      for (const [i, x] of [[0, 0], [1, half]]) {
        r.setViewport(x, 0, half, h);
        r.setScissor(x, 0, half, h);
        r.render(this.instances[i].scene, this.camera);
        r.setViewport(x + half - s - 8, h - s - 8, s, s);
        r.setScissor(x + half - s - 8, h - s - 8, s, s);
        r.render(this.instances[i].scene, this.top);
      }
      return;
    }
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    r.setViewport(0, 0, w, h);
    r.setScissor(0, 0, w, h);
    r.render(this.instances[0].scene, this.camera);
    const s = Math.floor(Math.min(w, h) * 0.3);
    r.setViewport(w - s - 8, h - s - 8, s, s);
    r.setScissor(w - s - 8, h - s - 8, s, s);
    r.render(this.instances[0].scene, this.top);
  }
}

// Plays pose clips (one per view instance) at the control rate against the clock: the step
// shown is the time since play began × the rate (a slow page skips drawing, never slows the
// motion), and poses between two steps are blended. Play/pause, scrub.
export class Player {
  constructor(view, onChange) {
    this.view = view;
    this.onChange = onChange;
    this.clips = [];
    this.t = 0;
    this.playing = false;
    this.hz = 20;
    this.t0 = 0;
    this.raf = null;
    this.bufs = [];
  }

  get length() { return this.clips.length ? Math.max(...this.clips.map((c) => c.length)) : 0; }

  load(clips, hz) {
    this.stop();
    this.clips = clips;
    this.hz = hz || 20;
    this.t = 0;
    this.show(0);
  }

  // Show time tf (in steps, fractional) of every clip.
  show(tf) {
    this.clips.forEach((c, i) => {
      if (!c.length) return;
      const k = Math.min(Math.floor(tf), c.length - 1), f = tf - k;
      if (f > 0 && k + 1 < c.length) {
        if (!this.bufs[i] || this.bufs[i].length !== c[k].length) this.bufs[i] = new Float32Array(c[k].length);
        this.view.pose(blendPoses(c[k], c[k + 1], f, this.bufs[i]), i);
      } else {
        this.view.pose(c[k], i);
      }
    });
    const step = Math.min(Math.floor(tf), Math.max(0, this.length - 1));
    const changed = step !== this.shownStep;
    this.t = step;
    this.shownStep = step;
    if (changed || !this.playing) this.onChange(this);
  }

  seek(t) {
    this.t = Math.max(0, Math.min(this.length - 1, t | 0));
    this.shownStep = -1;
    this.show(this.t);
  }

  play() {
    if (!this.length) return;
    if (this.t >= this.length - 1) this.t = 0;
    this.playing = true;
    this.t0 = performance.now() - (1000 * this.t) / this.hz;
    cancelAnimationFrame(this.raf);
    const tick = (now) => {
      if (!this.playing) return;
      const tf = ((now - this.t0) * this.hz) / 1000;
      if (tf >= this.length - 1) { this.show(this.length - 1); this.pause(); return; }
      this.show(Math.max(0, tf));
      this.raf = requestAnimationFrame(tick);
    };
    this.raf = requestAnimationFrame(tick);
    this.onChange(this);
  }

  pause() {
    this.playing = false;
    cancelAnimationFrame(this.raf);
    this.raf = null;
    this.onChange(this);
  }

  toggle() { if (this.playing) this.pause(); else this.play(); }

  stop() {
    this.pause();
    this.clips = [];
  }
}
