// Teleoperation: keyboard and gamepad (the browser's Gamepad API) to the action vector.
// Motion keys move the gripper in the world frame (W/S: +x/-x, A/D: +y/-y, R/F: up/down,
// Q/E: yaw); Shift makes every motion 30% as fast; G opens/closes the gripper. The command is
// a vector over the task's action names, each in [-1, 1].

export const MOTION_KEYS = {
  KeyW: ['dx', 1], KeyS: ['dx', -1],
  KeyA: ['dy', 1], KeyD: ['dy', -1],
  KeyR: ['dz', 1], KeyF: ['dz', -1],
  KeyQ: ['dyaw', 1], KeyE: ['dyaw', -1],
};
export const PRECISE = 0.3;
const DEADZONE = 0.15;

export class Teleop {
  constructor(actionNames, onChange) {
    this.names = actionNames;
    this.onChange = onChange;
    this.held = new Set();
    this.precise = false;
    this.gripperClosed = false;
    this.pad = null;
    this.padIndex = null;
    this.padButtons = [];
    this.last = '';
    this.onPadButton = () => {};
  }

  setNames(names) { this.names = names; this.emit(true); }

  reset() {
    this.held.clear();
    this.gripperClosed = false;
    this.emit(true);
  }

  // Returns true when the key was a teleoperation key (the caller then prevents its default).
  keydown(e) {
    if (e.code in MOTION_KEYS) {
      this.held.add(e.code);
    } else if (e.key === 'Shift') {
      this.precise = true;
    } else if (e.code === 'KeyG') {
      if (!e.repeat) this.gripperClosed = !this.gripperClosed;
    } else {
      return false;
    }
    this.emit();
    return true;
  }

  keyup(e) {
    if (e.code in MOTION_KEYS) this.held.delete(e.code);
    else if (e.key === 'Shift') this.precise = false;
    else return false;
    this.emit();
    return true;
  }

  releaseAll() {
    this.held.clear();
    this.precise = false;
    this.emit();
  }

  get moving() { return this.held.size > 0 || (this.pad !== null && this.pad.some((v) => v !== 0)); }

  vector() {
    const v = Object.fromEntries(this.names.map((n) => [n, 0]));
    for (const code of this.held) {
      const [name, sign] = MOTION_KEYS[code];
      if (name in v) v[name] += sign;
    }
    if (this.pad) {
      const [dx, dy, dz, dyaw] = this.pad;
      v.dx += dx; v.dy += dy; v.dz += dz; v.dyaw += dyaw;
    }
    const scale = this.precise ? PRECISE : 1;
    const out = this.names.map((n) => Math.max(-1, Math.min(1, v[n] * scale)));
    const g = this.names.indexOf('gripper');
    if (g >= 0) out[g] = this.gripperClosed ? 1 : -1;
    return out.map((x) => Math.round(x * 1000) / 1000);
  }

  emit(force = false) {
    const a = this.vector();
    const key = a.join(',');
    if (force || key !== this.last) {
      this.last = key;
      this.onChange(a);
    }
  }

  // Gamepad: left stick moves in x/y, right stick up/down and yaw; A toggles the gripper.
  pollGamepad() {
    const pads = navigator.getGamepads ? Array.from(navigator.getGamepads()).filter(Boolean) : [];
    const pad = pads[0];
    if (!pad) { if (this.pad) { this.pad = null; this.emit(); } return false; }
    const dz = (x) => (Math.abs(x) < DEADZONE ? 0 : Math.round(x * 100) / 100);
    const ax = pad.axes;
    this.pad = [-dz(ax[1] || 0), -dz(ax[0] || 0), -dz(ax[3] || 0), -dz(ax[2] || 0)];
    pad.buttons.forEach((b, i) => {
      const was = this.padButtons[i] || false;
      if (b.pressed && !was) {
        if (i === 0) this.gripperClosed = !this.gripperClosed;
        else this.onPadButton(i);
      }
      this.padButtons[i] = b.pressed;
    });
    this.emit();
    return true;
  }
}
