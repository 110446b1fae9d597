// A keyboard "operator" for the browser tests: runs in the page, reads the gripper's and the
// goal's positions from the view, and presses and releases the teleoperation keys (keydown /
// keyup events on the document, as a person's keyboard would) to drive reach-pillar past the
// pillar on the left (side = 1, the base operator's route) or the right (side = -1).
// Running in the page keeps the loop free of the test process's round trips, which on a
// loaded machine take long enough to overshoot. Returns a promise of what it saw: the
// indicator states, the last one, how often it turned red, and the route's phase.
(side) => new Promise((resolve) => {
  const held = new Set();
  const seen = new Set();
  let phase = 0;
  let started = false;
  const press = (code, down) => {
    const key = code === 'Shift' ? 'Shift' : code.replace('Key', '').toLowerCase();
    document.dispatchEvent(new KeyboardEvent(down ? 'keydown' : 'keyup',
      { code: code === 'Shift' ? 'ShiftLeft' : code, key, bubbles: true, shiftKey: code === 'Shift' && down }));
  };
  const want = (keys) => {
    for (const k of [...held]) if (!keys.has(k)) { press(k, false); held.delete(k); }
    for (const k of keys) if (!held.has(k)) { press(k, true); held.add(k); }
  };
  const axis = (keys, d, pos, neg, db) => { if (d > db) keys.add(pos); else if (d < -db) keys.add(neg); };
  let last = 'none';
  let reds = 0;
  const timer = setInterval(() => {
    const state = document.body.dataset.state;
    if (state === 'running') {  // the indicator resets once the episode is over
      const ind = document.getElementById('indicator').dataset.state;
      if (ind !== last && ind === 'red') reds += 1;
      seen.add(ind);
      last = ind;
    }
    if (started && state !== 'running') {
      want(new Set());
      clearInterval(timer);
      resolve({ seen: [...seen], last, reds, phase });
      return;
    }
    if (state === 'running') started = true;
    const e = window.elicit.bodyPosition('gripper');
    const g = window.elicit.bodyPosition('goal');
    if (!e || !g) return;
    const keys = new Set();
    if (phase === 0) {
      keys.add('KeyW');
      axis(keys, side * 0.09 - e[1], 'KeyA', 'KeyD', 0.008);
      if (e[0] >= -0.05) phase = 1;
    }
    if (phase === 1) {
      keys.add('KeyW');
      axis(keys, g[2] - e[2], 'KeyR', 'KeyF', 0.006);
      axis(keys, side * 0.09 - e[1], 'KeyA', 'KeyD', 0.012);
      if (e[0] >= 0.06) phase = 2;
    }
    if (phase === 2) {
      const d = [g[0] - e[0], g[1] - e[1], g[2] - e[2]];
      const near = Math.hypot(...d) < 0.05;
      const db = near ? 0.003 : 0.01;
      axis(keys, d[0], 'KeyW', 'KeyS', db);
      axis(keys, d[1], 'KeyA', 'KeyD', db);
      axis(keys, d[2], 'KeyR', 'KeyF', db);
      if (near) keys.add('Shift');
    }
    want(keys);
  }, 15);
})
