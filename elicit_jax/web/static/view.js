// The 3-D view: a three.js scene built once from the server's geom description, posed by
// streamed body poses. Z is up (MuJoCo's convention). Depth cues: shadows on the floor and a
// top-down inset in the corner. A split mode shows two copies of the scene side by side (an
// operator's window beside the retrieved base segment). Renders only when something changed.
import * as THREE from './three/three.module.js';
import { OrbitControls } from './three/OrbitControls.js';

const SOFTWARE_PIXELS = 160000;
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

function buildInstance(desc, shadowSize) {
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xeef1f5);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8f99, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 2.2);
  sun.position.set(-0.3, -0.4, 1.2);
  sun.target.position.set(0, 0, 0);
  sun.castShadow = true;
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
    const mat = item.type === 'plane'
      ? new THREE.MeshStandardMaterial({ color: new THREE.Color(r, g, b), roughness: 1 })
      : new THREE.MeshStandardMaterial({
        color: new THREE.Color(r, g, b), roughness: 0.6, metalness: 0.05,
        transparent: alpha < 1, opacity: alpha,
      });
    const mesh = new THREE.Mesh(geom, mat);
    mesh.name = item.name;
    mesh.position.set(...item.pos);
    mesh.quaternion.set(item.quat[1], item.quat[2], item.quat[3], item.quat[0]);
    mesh.castShadow = item.type !== 'plane' && alpha >= 1;
    mesh.receiveShadow = true;
    bodies[item.body].add(mesh);
  }
  return { scene, bodies };
}

export class View {
  constructor(container) {
    this.container = container;
    // Software WebGL (no GPU): no multisampling, and at most SOFTWARE_PIXELS pixels drawn per
    // frame, or drawing stalls the page (setFullQuality(true) lifts the cap, e.g. for a
    // screenshot).
    this.software = softwareRenderer();
    this.fullQuality = false;
    this.renderer = new THREE.WebGLRenderer({ antialias: !this.software });
    this.renderer.shadowMap.enabled = true;
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
    new ResizeObserver(() => this.dirty()).observe(container);
    const loop = () => {
      if (this._dirty) this.render();
      requestAnimationFrame(loop);
    };
    requestAnimationFrame(loop);
  }

  build(desc) {
    this.names = desc.bodies;
    const shadow = this.software ? 512 : 2048;
    this.instances = [buildInstance(desc, shadow), buildInstance(desc, shadow)];
    this.dirty();
  }

  resetCamera() {
    this.camera.position.copy(HOME.position);
    this.controls.target.copy(HOME.target);
    this.controls.update();
    this.dirty();
  }

  dirty() { this._dirty = true; }

  setFullQuality(on) {
    this.fullQuality = on;
    this.size = '';
    this.render();
  }

  // poses: Float32Array of nbody * 7 (x, y, z, qw, qx, qy, qz), into instance i.
  pose(poses, i = 0) {
    const inst = this.instances[i];
    if (!inst) return;
    const n = Math.min(inst.bodies.length, poses.length / 7);
    for (let b = 0; b < n; b++) {
      const o = b * 7;
      inst.bodies[b].position.set(poses[o], poses[o + 1], poses[o + 2]);
      inst.bodies[b].quaternion.set(poses[o + 4], poses[o + 5], poses[o + 6], poses[o + 3]);
    }
    if (i === 0) this.last = poses;
    this.dirty();
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
    const w = this.container.clientWidth, h = this.container.clientHeight;
    if (!w || !h || !this.instances.length) return;
    const r = this.renderer;
    if (this.size !== `${w}x${h}`) {
      this.size = `${w}x${h}`;
      const ratio = this.software && !this.fullQuality
        ? Math.min(1, Math.sqrt(SOFTWARE_PIXELS / (w * h)))
        : Math.min(window.devicePixelRatio || 1, 2);
      r.setPixelRatio(ratio);
      r.setSize(w, h, false);
    }
    if (this.split) {
      const half = Math.floor(w / 2);
      this.camera.aspect = half / h;
      this.camera.updateProjectionMatrix();
      for (const [i, x] of [[0, 0], [1, half]]) {
        r.setViewport(x, 0, half, h);
        r.setScissor(x, 0, half, h);
        r.render(this.instances[i].scene, this.camera);
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

// Plays pose clips (one per view instance) at the control rate, with play/pause and scrub.
export class Player {
  constructor(view, onChange) {
    this.view = view;
    this.onChange = onChange;
    this.clips = [];
    this.t = 0;
    this.playing = false;
    this.hz = 20;
    this.timer = null;
  }

  get length() { return this.clips.length ? Math.max(...this.clips.map((c) => c.length)) : 0; }

  load(clips, hz) {
    this.stop();
    this.clips = clips;
    this.hz = hz || 20;
    this.t = 0;
    this.show();
  }

  show() {
    this.clips.forEach((c, i) => {
      if (c.length) this.view.pose(c[Math.min(this.t, c.length - 1)], i);
    });
    this.onChange(this);
  }

  seek(t) {
    this.t = Math.max(0, Math.min(this.length - 1, t | 0));
    this.show();
  }

  play() {
    if (!this.length) return;
    if (this.t >= this.length - 1) this.t = 0;
    this.playing = true;
    clearInterval(this.timer);
    this.timer = setInterval(() => {
      if (this.t >= this.length - 1) { this.pause(); return; }
      this.t += 1;
      this.show();
    }, 1000 / this.hz);
    this.onChange(this);
  }

  pause() {
    this.playing = false;
    clearInterval(this.timer);
    this.timer = null;
    this.onChange(this);
  }

  toggle() { if (this.playing) this.pause(); else this.play(); }

  stop() {
    this.pause();
    this.clips = [];
  }
}
