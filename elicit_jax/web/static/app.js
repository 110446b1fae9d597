// The operator's page: one WebSocket to the server, screens chosen from the server's state.
// Screens: welcome (name) → practice → prompt (replays) → demonstrate (live indicator) →
// review (verdict, flagged windows beside the base segments) → progress → … → done.
// The server is the authority on the session; the page keeps only what it shows.
import { View, Player } from './view.js';
import { Teleop, MOTION_KEYS } from './teleop.js';

const $ = (id) => document.getElementById(id);
const NAME_KEY = 'elicit-jax-name';
const NAME_RE = /^[A-Za-z0-9][A-Za-z0-9_-]{0,39}$/;
const KEY_RE = /^[A-Za-z0-9_-]{16,64}$/;
const FATAL_CODES = [1003, 1008, 1009, 4001, 4002, 4003, 4005, 4006];
const PAUSED = 4004;  // the experimenter paused this operator: keep retrying quietly
const GOALS = {
  'reach-pillar': 'Bring the gripper to the green ball on the far side of the pillar.',
  'square-nut': 'Pick up the square nut by its handle and drop it over the square peg.',
  'round-nut': 'Pick up the round nut by its handle and drop it over the round peg.',
  'hammer-drawer': 'Pick up the hammer and put it into the drawer.',
  'robosuite-square': 'Pick up the square nut by its handle and put it onto the square peg.',
  'robosuite-round': 'Pick up the round nut by its handle and put it onto the round peg.',
};

// The operator's secret key: issued by the server at the first visit (a 'key' message) or in
// the experimenter's link (#op=NAME&key=KEY, read once and removed from the address bar).
// A link pasted into an open tab changes only the hash: it is taken then too (see 'hashchange').
const keyKey = (name) => `elicit-jax-key:${name}`;
function takeLink() {
  const h = new URLSearchParams(location.hash.slice(1));
  if (!NAME_RE.test(h.get('op') || '') || !KEY_RE.test(h.get('key') || '')) return null;
  localStorage.setItem(NAME_KEY, h.get('op'));
  localStorage.setItem(keyKey(h.get('op')), h.get('key'));
  history.replaceState(null, '', location.pathname + location.search);
  return h.get('op');
}
takeLink();

const S = {
  name: localStorage.getItem(NAME_KEY),
  ws: null, retries: 0, fatal: '',
  welcome: null, state: null, phase: null,
  episode: null, frames: new Map(), frameInfo: null,
  indicators: [], lastIndicator: null,
  prompt: null, promptClips: [], promptIndex: 0, promptDismissed: false,
  lastEnd: null, review: null, reviewClips: { yours: [], base: [] }, windowIndex: 0,
  reviewStep: 'review', acked: -1, control: false,
  screen: '', viewKey: '',
};

const view = new View($('view'));
const player = new Player(view, updateReplayBar);
const teleop = new Teleop([], (a) => send({ type: 'action', a }));
teleop.onPadButton = (i) => { if (i === 1) toggleControl(); else if (i === 9) onEnter(); };
window.elicit = { view, state: S, bodyPosition: (name) => view.bodyPosition(name) };

// --- connection -------------------------------------------------------------------------
function setConn(kind, text) {
  $('conn').dataset.conn = kind;
  $('conn').textContent = text;
}

function send(msg) {
  if (S.ws && S.ws.readyState === WebSocket.OPEN) S.ws.send(JSON.stringify(msg));
}

function connect() {
  if (S.ws || !S.name) return;
  const token = new URLSearchParams(location.search).get('token');
  const scheme = location.protocol === 'https:' ? 'wss' : 'ws';
  const url = `${scheme}://${location.host}/ws${token ? `?token=${encodeURIComponent(token)}` : ''}`;
  const ws = new WebSocket(url);
  ws.binaryType = 'arraybuffer';
  S.ws = ws;
  setConn('connecting', 'connecting…');
  ws.onopen = () => {
    S.retries = 0;
    setConn('open', 'connected');
    const key = localStorage.getItem(keyKey(S.name));
    ws.send(JSON.stringify(key ? { type: 'hello', name: S.name, key } : { type: 'hello', name: S.name }));
  };
  ws.onmessage = (e) => {
    if (typeof e.data === 'string') onText(JSON.parse(e.data));
    else onBinary(e.data);
  };
  ws.onclose = (e) => {
    if (S.ws === ws) S.ws = null;
    teleop.releaseAll();
    if (e.code === 4000) return fail('This session was opened in another window or tab.');
    if (FATAL_CODES.includes(e.code)) return fail(e.reason || `connection refused (${e.code})`);
    if (!S.name) return;
    setConn('lost', e.code === PAUSED ? e.reason : 'reconnecting…');
    const delay = Math.min(5000, 500 * 2 ** S.retries++);
    setTimeout(connect, delay);
  };
}

function fail(message) {
  S.fatal = message;
  setConn('lost', 'disconnected');
  render();
}

setInterval(() => send({ type: 'ping', t: Date.now() / 1000 }), 15000);

// --- messages ----------------------------------------------------------------------------
function onBinary(buf) {
  const dv = new DataView(buf);
  const kind = dv.getUint8(0);
  const nbody = dv.getUint16(2, true);
  if (kind === 1) {
    const info = {
      operator: (dv.getUint8(1) & 1) === 1, episode: dv.getUint32(4, true),
      step: dv.getUint32(8, true), m: dv.getFloat32(12, true),
    };
    const poses = new Float32Array(buf, 16, nbody * 7);
    S.frames.set(info.episode, poses);
    for (const k of S.frames.keys()) if (k < info.episode - 2) S.frames.delete(k);
    S.frameInfo = info;
    const glide = S.welcome ? 1000 / S.welcome.control_hz : 50;
    if (S.viewKey === `live:${info.episode}` || S.viewKey === `end:${info.episode}`) view.pose(poses, 0, glide);
    soon(updateHud);
  } else if (kind === 2) {
    const role = dv.getUint8(1), id = dv.getUint32(4, true), T = dv.getUint32(8, true);
    const data = new Float32Array(buf, 16, T * nbody * 7);
    const clip = Array.from({ length: T }, (_, t) => data.subarray(t * nbody * 7, (t + 1) * nbody * 7));
    if (role === 0) S.promptClips[id] = clip;
    else if (role === 1) S.reviewClips.yours[id] = clip;
    else S.reviewClips.base[id] = clip;
    render();
  }
}

function onText(msg) {
  switch (msg.type) {
    case 'welcome':
      S.welcome = msg;
      S.fatal = '';
      S.prompt = null; S.promptClips = []; S.review = null;
      S.reviewClips = { yours: [], base: [] }; S.indicators = []; S.lastIndicator = null;
      S.lastEnd = null; S.frames.clear();
      document.body.dataset.mode = msg.mode;
      document.body.dataset.dagger = String(msg.dagger);
      $('task').textContent = msg.task;
      $('who').textContent = msg.name;
      teleop.setNames(msg.action_names);
      break;
    case 'scene': view.build(msg); break;
    case 'event': onEvent(msg.event); break;
    case 'indicators':  // a reattach: the episode's steps so far and its live state
      S.indicators = msg.items;
      S.lastIndicator = msg.last;
      break;
    case 'prompt':
      S.prompt = msg; S.promptClips = []; S.promptIndex = 0; S.promptDismissed = false;
      break;
    case 'review':
      S.review = msg; S.reviewClips = { yours: [], base: [] }; S.windowIndex = 0;
      break;
    case 'state':
      S.state = msg;
      document.body.dataset.state = msg.state;
      break;
    case 'error': S.error = msg.message; break;
    case 'key': localStorage.setItem(keyKey(msg.name), msg.key); showLink(); break;
    default: return;
  }
  render();
}

function onEvent(ev) {
  switch (ev.kind) {
    case 'phase': S.phase = ev; break;
    case 'episode-start':
      S.episode = ev;
      S.spokenSecond = null;
      S.indicators = []; S.lastIndicator = null;
      S.control = !ev.dagger;
      teleop.gripperClosed = false;
      teleop.emit(true);
      break;
    case 'indicator':
      S.indicators.push([ev.step, ev.compatibility, ev.incompatible ? 1 : 0, ev.live ? ev.live.light : '']);
      if (ev.live && ev.live.doomed && !(S.lastIndicator && S.lastIndicator.live && S.lastIndicator.live.doomed)) {
        announce(`This try can no longer be accepted: ${ev.live.red} red steps, ${ev.live.allowed} allowed. Backspace stops it.`);
      }
      S.lastIndicator = ev;
      soon(updateIndicator, 100);
      return;
    case 'episode-end':
      S.lastEnd = ev;
      announce(endWords(ev));
      S.reviewStep = 'review';
      if (S.review && S.review.episode !== ev.episode) S.review = null;
      break;
    default: break;
  }
}

// --- screens -----------------------------------------------------------------------------
const TOP_BAR_SCREENS = new Set(['practice', 'prompt', 'demonstrate', 'review', 'progress', 'retrain', 'done']);

function informed() { return S.welcome && S.welcome.mode === 'informed'; }

const VERDICT_WORDS = { accepted: 'Accepted', rejected: 'Not accepted', failed: 'Not completed', unused: 'Nothing to record' };

// The verdict's words: "you gave up" is the operator's choice, "not completed" the clock's.
function verdictWord(verdict, end) {
  if (verdict === 'failed' && end && end.gave_up) return 'You gave up';
  return VERDICT_WORDS[verdict] || verdict;
}

function endWords(ev) {
  if (ev.gave_up) return 'You gave up this try.';
  if (!ev.success) return 'Time is up: the task was not completed.';
  return ev.episode_kind === 'practice' ? 'Solved.' : 'Solved: recorded.';
}

// Screen readers hear verdicts and ends of episodes (the #announce region is aria-live).
function announce(text) {
  const el = $('announce');
  if (el.textContent === text) el.textContent = '';
  el.textContent = text;
}

// Text and the strip change with every step (20 a second); they are redrawn at most 5 (the
// indicator 10) times a second: each redraw of the page costs CPU that a software-rendered
// view needs more.
const pending = new Set();
function soon(fn, ms = 200) {
  if (pending.has(fn)) return;
  pending.add(fn);
  setTimeout(() => { pending.delete(fn); fn(); }, ms);
}

function plural(n, word) { return `${n} ${word}${n === 1 ? '' : 's'}`; }

// Whole steps the rule allows for `scored` scored steps (it rejects above rule.allowed).
function allowedSteps(allowed) { return Math.floor(allowed + 1e-9); }

function pickScreen() {
  if (!S.name) return 'welcome';
  if (S.fatal) return 'error';
  const st = S.state;
  if (!st || !S.welcome) return 'loading';
  if (st.state === 'error') return 'error';
  if (st.state === 'opening') return 'loading';
  const end = S.lastEnd;
  if (end && S.acked !== end.episode && (st.review_pending || st.state === 'done')) {
    const judged = end.episode_kind === 'demonstration' && informed();
    return judged && S.reviewStep === 'review' ? 'review' : 'progress';
  }
  if (st.state === 'busy') return 'retrain';
  if (st.state === 'done') return 'done';
  const wantPrompt = st.prompt_pending || S.promptRequested;
  if (st.episode_kind === 'demonstration' && wantPrompt && S.prompt && !S.promptDismissed) return 'prompt';
  return st.episode_kind === 'practice' ? 'practice' : 'demonstrate';
}

function render() {
  const screen = pickScreen();
  if (screen !== S.screen) window.scrollTo(0, 0);  // a narrow page scrolls: start at the view
  S.screen = screen;
  document.body.dataset.screen = screen;
  const w = S.welcome, st = S.state;
  const counts = st && st.counts;
  if (counts) {
    const word = informed() ? 'accepted' : 'recorded';
    $('progress').textContent = `${word} ${counts.accepted} of ${counts.wanted}`;
    $('progress').dataset.accepted = counts.accepted;
    $('progress').dataset.wanted = counts.wanted;
  }
  // the screen the operator is on, not the session's phase: by the time the review shows,
  // the session has already begun the next episode (its phase reads 'demonstrate')
  $('phase').textContent = TOP_BAR_SCREENS.has(screen) ? screen : (S.phase ? S.phase.phase : '');
  if (w) {
    const goal = GOALS[w.task] || 'Solve the task.';
    $('task-goal').textContent = goal;
    $('demo-goal').textContent = goal;
    $('rule-text').textContent = w.rule_words || '';
    for (const el of document.querySelectorAll('.horizon')) el.textContent = `${w.horizon} steps (${(w.horizon / w.control_hz).toFixed(0)} s)`;
  }
  if (st && counts) {
    $('practice-n').textContent = `${Math.min(counts.practice + 1, w.practice)} of ${w.practice}`;
    $('demo-n').textContent = `${counts.accepted + 1} of ${counts.wanted}`;
  }
  if (screen === 'prompt') renderPrompt();
  if (screen === 'review') renderReview();
  if (screen === 'progress') renderProgress();
  if (screen === 'done') renderDone();
  if (screen === 'error') $('error-text').textContent = S.fatal || (st && st.message) || S.error || '';
  if (screen === 'retrain') $('retrain-text').textContent = 'The robot is learning from the demonstrations accepted so far. This takes a minute or two.';
  $('indicator-box').hidden = !(informed() && screen === 'demonstrate');
  applyView(screen);
  updateIndicator();
  updateHud();
}

function renderPrompt() {
  const p = S.prompt;
  $('prompt-message').textContent = `Here ${p.episodes.length === 1 ? 'is one demonstration' : `are ${p.episodes.length} demonstrations`} the robot reproduces best. Do it like this.`;
  const list = $('prompt-list');
  if (list.dataset.for !== JSON.stringify(p.episodes.map((e) => e.base_episode))) {
    list.dataset.for = JSON.stringify(p.episodes.map((e) => e.base_episode));
    list.replaceChildren(...p.episodes.map((e, i) => {
      const b = document.createElement('button');
      b.type = 'button';
      b.innerHTML = `Demonstration ${i + 1} <span class="meta">${e.length} steps${e.exact ? '' : ' · gripper only'}</span>`;
      b.onclick = () => { S.promptIndex = i; render(); player.play(); };
      return b;
    }));
  }
  [...list.children].forEach((b, i) => b.setAttribute('aria-pressed', String(i === S.promptIndex)));
}

function renderReview() {
  const r = S.review;
  const v = $('verdict');
  if (!r) { v.textContent = '…'; v.dataset.verdict = ''; return; }
  v.dataset.verdict = r.verdict;
  const end = S.lastEnd && S.lastEnd.episode === r.episode ? S.lastEnd : null;
  v.textContent = verdictWord(r.verdict, end);
  const allowed = allowedSteps(r.allowed_steps ?? r.scored * 0.05);
  const red = `${plural(r.incompatible, 'red step')} of ${allowed} allowed (${r.scored} steps)`;
  const text = r.verdict === 'rejected'
    ? `${red}: too many of your steps did not fit the robot's motion. Where it differed most:`
    : r.verdict === 'accepted'
      ? `${red}: within the rule. Thank you!`
      : end && end.gave_up ? `You ended this try after ${end.length} steps; it does not count. Try again when ready.`
        : r.verdict === 'failed' ? `The time ran out (${S.welcome.horizon} steps) before the task was done; this try does not count.` : r.text;
  $('review-text').textContent = text;
  if (S.announcedReview !== r.episode) { S.announcedReview = r.episode; announce(`${v.textContent}. ${text}`); }
  const list = $('review-windows');
  if (list.dataset.for !== String(r.episode)) {
    list.dataset.for = String(r.episode);
    list.replaceChildren(...r.windows.map((win, i) => {
      const b = document.createElement('button');
      b.type = 'button';
      b.className = 'window';
      const head = document.createElement('b');
      head.textContent = `${i + 1}. Steps ${win.start}–${win.stop - 1}`;
      const meta = document.createElement('span');
      meta.className = 'meta';
      const reds = win.m.filter((m) => m !== null && m <= 0).length;
      meta.textContent = ` · ${plural(reds, 'red step')} of ${win.m.length}`;
      const words = document.createElement('span');
      words.className = 'plain';
      words.textContent = (win.plain && win.plain.length ? win.plain.join('; ') : win.text.replace(/^steps [^:]*: /, '').replace(/ — compare.*$/, '')) + '.';
      b.append(head, meta, document.createElement('br'), words);
      b.onclick = () => selectWindow(i);
      return b;
    }));
  }
  [...list.children].forEach((b, i) => b.setAttribute('aria-pressed', String(i === S.windowIndex)));
  $('review-compare').hidden = !r.windows.length;
  drawStrip($('review-strip'), r.indicators, S.welcome.horizon, r.windows.map((x) => x.episode_steps));
}

function selectWindow(i) {
  if (!S.review || i < 0 || i >= S.review.windows.length) return;
  S.windowIndex = i;
  render();
  player.play();
}

function renderProgress() {
  const c = S.state.counts, end = S.lastEnd, w = S.welcome;
  let last = '';
  if (end) {
    if (end.episode_kind === 'practice') last = `Practice ${Math.min(c.practice, w.practice)} of ${w.practice} done${end.success ? ': solved' : ''}.`;
    else if (!informed()) last = end.success ? 'Recorded: the task was completed.' : end.gave_up ? 'You gave up: this try does not count.' : 'Not completed: this try does not count.';
    else if (S.review) {
      const r = S.review, pct = (100 * r.fraction).toFixed(1);
      const word = verdictWord(r.verdict, end);
      last = r.scored && r.verdict !== 'failed' ? `${word}: ${plural(r.incompatible, 'red step')} of ${r.scored} (${pct}%).` : `${word}.`;
    }
  }
  $('last-result').textContent = last;
  $('progress-text').textContent = informed()
    ? `Accepted so far: ${c.accepted} of ${c.wanted} (${c.rejected} not accepted, ${c.failed} not completed).`
    : `Recorded so far: ${c.accepted} of ${c.wanted}.`;
  const rows = (S.state.history || []).filter((h) => h.kind === 'demonstration');
  $('history').replaceChildren(...rows.map((h) => {
    const li = document.createElement('li');
    li.dataset.verdict = h.verdict;
    const word = informed() ? h.verdict : (h.verdict === 'accepted' ? 'recorded' : 'not completed');
    li.textContent = `${word} (${h.length} steps)`;
    return li;
  }));
  const next = S.state.state === 'done' ? 'Finish' : S.state.episode_kind === 'practice' ? 'Next practice' : `Start demonstration ${c.accepted + 1}`;
  $('next').textContent = `${next} (Enter)`;
}

function renderDone() {
  const c = S.state.counts;
  $('done-text').textContent = `Your session is complete: ${c.accepted} demonstration${c.accepted === 1 ? '' : 's'} ${informed() ? 'accepted' : 'recorded'}. You can close this page.`;
}

// --- the view ------------------------------------------------------------------------------
function applyView(screen) {
  let key, clips = null, split = false, labels = ['', ''];
  const ep = S.episode ? S.episode.episode : -1;
  if (screen === 'prompt') {
    key = `prompt:${S.promptIndex}`;
    clips = S.promptClips[S.promptIndex] ? [S.promptClips[S.promptIndex]] : null;
  } else if (screen === 'review' && S.review && S.review.windows.length) {
    const i = S.windowIndex, win = S.review.windows[i];
    key = `review:${S.review.episode}:${i}`;
    const a = S.reviewClips.yours[i], b = S.reviewClips.base[i];
    clips = a && b ? [a, b] : null;
    split = true;
    labels = [`you (orange): steps ${win.start}–${win.stop - 1}`, `base demo ${win.base_episode} (blue): steps ${win.base_start}–${win.base_stop - 1}`];
  } else if ((screen === 'review' || screen === 'progress') && S.lastEnd) {
    key = `end:${S.lastEnd.episode}`;
  } else {
    key = `live:${ep}`;
  }
  const full = `${key}|${clips ? 'clips' : ''}`;
  if (full === S.viewFull) return;
  S.viewFull = full;
  S.viewKey = key;
  view.setSplit(split, labels);
  document.body.dataset.split = String(split);
  $('split-labels').hidden = !split;
  $('label-left').textContent = labels[0];
  $('label-right').textContent = labels[1];
  view.setTrails(clips && split ? clips.map(path) : null);
  if (clips) {
    player.load(clips, S.welcome ? S.welcome.control_hz : 20);
    $('replay-bar').hidden = false;
  } else {
    player.stop();
    $('replay-bar').hidden = true;
    const episode = Number(key.split(':')[1]);
    const frame = S.frames.get(episode);
    if (frame) view.pose(frame);
  }
}

// The gripper's positions along a clip (its trail).
function path(clip) {
  const b = view.names.indexOf((view.desc && view.desc.gripper) || 'gripper');
  return b < 0 ? null : clip.map((poses) => [poses[b * 7], poses[b * 7 + 1], poses[b * 7 + 2]]);
}

function updateReplayBar(p) {
  const scrub = $('replay-scrub');
  scrub.max = String(Math.max(0, p.length - 1));
  scrub.value = String(p.t);
  $('replay-play').textContent = p.playing ? 'pause' : 'play';
  $('replay-play').dataset.playing = String(p.playing);
  $('replay-step').textContent = p.length ? `step ${p.t + 1} / ${p.length}` : '';
}

// One live state from the server (elicit_jax/elicit/light.py), never contradicting the verdict:
// the light is this step's (green ✓ disc: fits; red ✗ square: does not — the rule counts it;
// grey ‖: you are not moving; grey ?: the robot has no data here), the count is the red steps
// against the allowance of a full-length episode (fixed), the line under it the verdict if
// the episode ended now, and once the red steps exceed the allowance the try can no longer
// be accepted: the box turns red and offers to stop.
const LIGHT_WORDS = {
  green: ['✓', 'fits'], red: ['✗', 'does not fit'],
  idle: ['‖', 'idle: you are not moving'], unfamiliar: ['?', 'no data here: the robot has never been here'],
  none: ['', 'waiting'],
};
function updateIndicator() {
  const ind = $('indicator');
  const li = S.lastIndicator, live = li && li.live;
  const last = S.indicators.length ? S.indicators[S.indicators.length - 1] : null;
  const light = live ? live.light : last ? (last[2] ? 'red' : 'fits') : 'none';
  const state = light === 'fits' ? 'green' : light;
  ind.dataset.state = state;
  ind.dataset.m = li && li.compatibility !== null ? li.compatibility.toFixed(3) : '';
  const [symbol, words] = LIGHT_WORDS[state] || LIGHT_WORDS.none;
  ind.textContent = symbol;
  $('m-value').textContent = words;
  const count = $('inc-count'), now = $('now-verdict'), stop = $('stop-try');
  const doomed = Boolean(live && live.doomed);
  $('indicator-box').dataset.doomed = String(doomed);
  stop.hidden = !doomed;
  if (live && doomed) {
    count.textContent = `✗ ${plural(live.red, 'red step')}, more than the ${live.allowed} allowed: this try can no longer be accepted.`;
    now.textContent = '';  // the stop button takes its place (the box keeps its height)
  } else if (live) {
    count.textContent = `${plural(live.red, 'red step')} of ${live.allowed} allowed · ${live.left} more allowed in a full ${live.horizon}-step episode`;
    now.textContent = live.accept_now
      ? `Solved now, it would be accepted (${live.red} of ${live.allowed_now} allowed at ${live.scored} steps).`
      : `Solved now, it would not be accepted (${live.red} red, ${live.allowed_now} allowed at ${live.scored} steps): more fitting steps raise it.`;
  } else {
    const w = S.welcome;
    count.textContent = w && w.allowed_at_horizon !== null && w.allowed_at_horizon !== undefined
      ? `no steps yet · ${w.allowed_at_horizon} red steps allowed in a full ${w.horizon}-step episode`
      : 'no steps yet';
    now.textContent = '';
  }
  count.dataset.over = String(doomed);
  drawStrip($('strip'), S.indicators, S.welcome ? S.welcome.horizon : 100, []);
}

function updateHud() {
  const f = S.frameInfo, w = S.welcome;
  const live = S.viewKey && S.viewKey.startsWith('live:');
  const running = S.state && S.state.state === 'running';
  $('hud-step').textContent = live && f && w ? `step ${f.step} / ${w.horizon}` : '';
  const cd = $('countdown');
  cd.hidden = !(live && w && (S.screen === 'practice' || S.screen === 'demonstrate'));
  if (!cd.hidden) {
    // the episode's own step, also while paused (a reload mid-episode keeps its progress)
    const step = f && S.episode && f.episode === S.episode.episode && (running || f.step > 0) ? f.step : 0;
    const left = Math.max(0, (w.horizon - step) / w.control_hz);
    const sec = Math.ceil(left);
    $('countdown-text').textContent = running ? `${sec} s left` : step > 0 ? `${sec} s left (paused: move to go on)` : `${sec} s once you start`;
    $('countdown-bar').style.transform = `scaleX(${(w.horizon - step) / w.horizon})`;
    cd.dataset.low = String(running && left <= 3);
    if (running && sec !== S.spokenSecond && (sec === 5 || sec === 0)) { S.spokenSecond = sec; announce(`${sec} seconds left`); }
  }
  const ctl = $('hud-control');
  if (w && w.dagger && live) {
    const mine = running && f ? f.operator : S.control;
    ctl.dataset.control = mine ? 'operator' : 'robot';
    ctl.textContent = mine ? 'YOU are in control (T hands back)' : 'ROBOT in control (T takes over)';
  } else {
    ctl.dataset.control = '';
    ctl.textContent = '';
  }
}

function drawStrip(canvas, items, horizon, windows) {
  const ctx = canvas.getContext('2d');
  const w = canvas.width, h = canvas.height;
  ctx.clearRect(0, 0, w, h);
  const last = items.length ? items[items.length - 1][0] + 1 : 1;
  const n = Math.max(horizon, last);
  const bw = w / n;
  ctx.fillStyle = 'rgba(214, 69, 69, 0.14)';
  for (const steps of windows) {
    if (steps.length) ctx.fillRect(steps[0] * bw, 0, (steps[steps.length - 1] - steps[0] + 1) * bw, h);
  }
  for (const [step, m, inc, light] of items) {
    if (m === null) continue;
    const grey = light === 'idle' || light === 'unfamiliar';  // neither fits nor counts
    ctx.fillStyle = inc ? '#d64545' : grey ? '#9aa3ae' : '#1f9d55';
    const bh = inc ? h - 4 : grey ? (h - 4) / 3 : Math.max(3, m * (h - 4));
    ctx.fillRect(step * bw, h - bh, Math.max(1, bw - 0.5), bh);
  }
}

// --- actions ---------------------------------------------------------------------------------
function start() {
  teleop.emit(true);
  if (S.welcome && S.welcome.dagger) send({ type: 'control', operator: S.control });
  send({ type: 'start' });
}

function dismissPrompt() {
  S.promptDismissed = true;
  S.promptRequested = false;
  render();
}

function toggleControl() {
  if (!S.welcome || !S.welcome.dagger) return;
  S.control = !S.control;
  send({ type: 'control', operator: S.control });
  updateHud();
}

function onEnter() {
  const st = S.state;
  switch (S.screen) {
    case 'prompt': dismissPrompt(); break;
    case 'practice':
    case 'demonstrate':
      // Without DAgger the clock starts with the first move (no idle steps get recorded).
      if (st && st.state === 'ready' && S.welcome.dagger) start();
      break;
    case 'review': S.reviewStep = 'progress'; render(); break;
    case 'progress':
      S.acked = S.lastEnd ? S.lastEnd.episode : -1;
      sessionStorage.setItem(ackKey(), String(S.acked));  // a reload does not show it again
      render();
      break;
    case 'error': reconnect(); break;
    default: break;
  }
}

function showLink() {
  const key = S.name && localStorage.getItem(keyKey(S.name));
  $('my-link').hidden = !key;
  if (key) $('my-link').href = `${location.pathname}${location.search}#op=${S.name}&key=${key}`;
}

function ackKey() { return `elicit-jax-acked:${S.name}`; }

function reconnect() {
  S.fatal = '';
  if (S.ws) S.ws.close();
  S.ws = null;
  connect();
  render();
}

document.addEventListener('keydown', (e) => {
  const t = e.target;
  if (t && t.tagName === 'INPUT' && t.type !== 'range') return;
  // a focused button or link (reached with Tab) takes Enter and Space itself
  const onControl = t && (t.tagName === 'BUTTON' || t.tagName === 'A' || t.tagName === 'SUMMARY');
  if ((e.code === 'Enter' || e.code === 'NumpadEnter' || e.code === 'Space') && onControl) return;
  if (e.code === 'Enter' || e.code === 'NumpadEnter') { e.preventDefault(); if (!e.repeat) onEnter(); return; }
  if (e.code === 'Space' && player.clips.length) { e.preventDefault(); player.toggle(); return; }
  if (S.screen === 'review' && /^Digit[1-9]$/.test(e.code)) { selectWindow(Number(e.code.slice(5)) - 1); return; }
  if (S.screen === 'prompt' && /^Digit[1-9]$/.test(e.code)) {
    const i = Number(e.code.slice(5)) - 1;
    if (S.prompt && i < S.prompt.episodes.length) { S.promptIndex = i; render(); player.play(); }
    return;
  }
  if (e.code === 'Backspace') {
    e.preventDefault();
    // running, or paused mid-episode after a reload (the server ends only a started episode)
    if (S.state && (S.state.state === 'running' || S.state.state === 'ready')) send({ type: 'give-up' });
    return;
  }
  if (e.code === 'KeyC') { view.resetCamera(); return; }
  if (e.code === 'KeyT') { if (!e.repeat) toggleControl(); return; }
  if ((S.screen === 'practice' || S.screen === 'demonstrate') && teleop.keydown(e)) {
    e.preventDefault();
    if (e.code in MOTION_KEYS && S.state && S.state.state === 'ready' && !S.welcome.dagger) start();
  }
});
document.addEventListener('keyup', (e) => { if (teleop.keyup(e)) e.preventDefault(); });
window.addEventListener('blur', () => teleop.releaseAll());

window.addEventListener('gamepadconnected', () => {
  const poll = () => { if (teleop.pollGamepad()) requestAnimationFrame(poll); };
  requestAnimationFrame(poll);
});

$('name-form').addEventListener('submit', (e) => {
  e.preventDefault();
  const name = $('name').value.trim();
  if (!NAME_RE.test(name)) { $('name').setCustomValidity('1–40 letters, digits, _ or -'); $('name').reportValidity(); return; }
  S.name = name;
  S.acked = Number(sessionStorage.getItem(ackKey()) ?? -1);
  localStorage.setItem(NAME_KEY, name);
  showLink();
  connect();
  render();
});
$('name').addEventListener('input', () => $('name').setCustomValidity(''));
$('change-name').addEventListener('click', (e) => {
  e.preventDefault();
  if (S.name) localStorage.removeItem(keyKey(S.name));  // a shared machine: the next person
  localStorage.removeItem(NAME_KEY);
  S.name = null; S.state = null; S.welcome = null; S.fatal = '';
  showLink();
  const ws = S.ws;
  S.ws = null;
  if (ws) ws.close();
  setConn('idle', 'not connected');
  render();
});
window.addEventListener('hashchange', () => {
  const name = takeLink();
  if (!name) return;
  if (name !== S.name) { S.state = null; S.welcome = null; }
  S.name = name;
  S.acked = Number(sessionStorage.getItem(ackKey()) ?? -1);
  showLink();
  reconnect();
});
$('prompt-done').onclick = () => dismissPrompt();
$('prompt-again').onclick = () => { if (S.prompt) { S.promptDismissed = false; S.promptRequested = true; render(); } };
$('review-done').onclick = () => { S.reviewStep = 'progress'; render(); };
$('next').onclick = () => onEnter();
$('stop-try').onclick = () => send({ type: 'give-up' });  // the server ends only a started episode
$('reconnect').onclick = () => reconnect();
$('replay-play').onclick = () => player.toggle();
$('replay-scrub').addEventListener('input', (e) => {
  const t = Number(e.target.value);
  player.pause();
  player.seek(t);
});

if (S.name) S.acked = Number(sessionStorage.getItem(ackKey()) ?? -1);
showLink();
render();
connect();
