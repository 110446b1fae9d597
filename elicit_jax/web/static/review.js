// The review page: the episode table (sortable by M, quality flag, operator, ...), an
// episode's replay in the same 3-D view as the operator page with its M strip, flags with
// reasons, and writing the selection. Talks to elicit_jax/web/review.py over JSON.
import { View, Player } from './view.js';

const $ = (id) => document.getElementById(id);
const state = { rows: [], sortKey: 'episode', sortDir: 'asc', current: null, m: null };
let view = null;
let player = null;

// Every call's failure becomes one plain sentence (never a JSON parse error): the server's
// own message when it sent one, else what the status means here.
async function api(path, body) {
  const opts = body === undefined ? {} : {
    method: 'POST', headers: { 'content-type': 'application/json' }, body: JSON.stringify(body),
  };
  let res;
  try {
    res = await fetch(path, { credentials: 'same-origin', cache: 'no-store', ...opts });
  } catch (e) {
    throw failure(0, 'the review server cannot be reached: is `elicit-jax review` still running?');
  }
  const text = await res.text();
  let data = null;
  try { data = JSON.parse(text); } catch (e) { data = null; }
  if (res.ok && data !== null) return data;
  const said = (data && data.error) || text.trim().split('\n')[0] || res.statusText;
  if (res.status === 403) {
    throw failure(403, `the review server refused this page (${said}): open the URL \`elicit-jax review\` printed again`);
  }
  throw failure(res.status, res.ok ? `the review server sent an answer this page cannot read (${res.status})` : said);
}

function failure(status, message) {
  const e = new Error(message);
  e.status = status;
  return e;
}

// A page-level message: what failed and what to do, until the next call succeeds.
function pageError(message) {
  $('page-error').textContent = message;
  $('page-error').hidden = !message;
}

function fmt(v, digits = 2) {
  if (v === null || v === undefined) return '–';
  return typeof v === 'number' && !Number.isInteger(v) ? v.toFixed(digits) : String(v);
}

function sortValue(row, key) {
  const v = row[key];
  if (typeof v === 'boolean') return v ? 1 : 0;
  return v === null || v === undefined ? -Infinity : v;
}

function renderTable() {
  const { sortKey, sortDir } = state;
  const rows = [...state.rows].sort((a, b) => {
    const x = sortValue(a, sortKey), y = sortValue(b, sortKey);
    const c = typeof x === 'string' ? x.localeCompare(y) : x - y;
    return (sortDir === 'asc' ? c : -c) || a.episode - b.episode;
  });
  for (const th of document.querySelectorAll('#episodes th')) {
    th.dataset.dir = th.dataset.key === sortKey ? sortDir : '';
  }
  const body = document.querySelector('#episodes tbody');
  body.replaceChildren(...rows.map((r) => {
    const tr = document.createElement('tr');
    tr.dataset.episode = r.episode;
    tr.dataset.flagged = String(r.flagged);
    tr.setAttribute('aria-selected', String(r.episode === state.current));
    const cells = [r.episode, r.operator, r.steps, fmt(r.m_mean), fmt(r.incompatible),
      r.quality_flagged === null ? '–' : (r.quality_flagged ? 'outlier' : 'ok'),
      r.flagged ? `flagged: ${r.reason}` : ''];
    cells.forEach((text, i) => {
      const td = document.createElement('td');
      td.textContent = String(text);
      if (i === 3 || i === 4) td.className = 'm-col';
      if (i === 5) td.className = r.quality_flagged ? 'q-col q-bad' : 'q-col';
      if (i === 5 && r.quality_flagged) td.title = r.quality_reason;
      if (i === 6) td.className = 'flag';
      tr.appendChild(td);
    });
    tr.addEventListener('click', () => select(r.episode));
    return tr;
  }));
  const flagged = state.rows.filter((r) => r.flagged).length;
  $('counts').textContent = `${state.rows.length} episodes, ${flagged} flagged`;
  $('counts').dataset.flagged = String(flagged);
}

async function refresh() {
  const data = await api('/api/episodes');
  state.rows = data.episodes;
  $('source').textContent = `${data.demos}${data.task ? ` (${data.task})` : ''}`;
  document.body.classList.toggle('no-m', !data.has_m);
  document.body.classList.toggle('no-quality', !data.has_quality);
  renderTable();
}

async function refreshOrSay() {
  try {
    await refresh();
    return true;
  } catch (e) {
    pageError(`Could not update the episode list: ${e.message}`);
    return false;
  }
}

function drawStrip() {
  const c = $('m-strip');
  const ctx = c.getContext('2d');
  ctx.clearRect(0, 0, c.width, c.height);
  const m = state.m;
  if (!m || !m.length) {
    ctx.fillStyle = '#667';
    ctx.fillText('no compatibility scores (--scores) for this episode', 8, 24);
    return;
  }
  const w = c.width / m.length;
  m.forEach((v, i) => {
    ctx.fillStyle = `rgb(${Math.round(220 * (1 - v))}, ${Math.round(170 * v + 40)}, 70)`;
    ctx.fillRect(i * w, 0, Math.ceil(w), c.height);
  });
  if (player) {
    ctx.fillStyle = '#000';
    ctx.fillRect(player.t * w, 0, Math.max(2, w / 3), c.height);
  }
}

function onPlayer(p) {
  $('scrub').max = String(Math.max(0, p.length - 1));
  $('scrub').value = String(p.t);
  $('step').textContent = p.length ? `step ${p.t + 1} / ${p.length}` : '';
  $('play').dataset.playing = String(p.playing);
  $('play').textContent = p.playing ? 'pause' : 'play';
  drawStrip();
}

// The replay shown is always the titled episode's: a new pick clears the old one first,
// and an answer for an episode no longer picked (clicked past, or failed) is dropped.
let picks = 0;
async function select(episode) {
  const pick = ++picks;
  state.current = episode;
  state.m = null;
  renderTable();
  const row = state.rows.find((r) => r.episode === episode);
  if (player) player.load([], 20);
  $('view').classList.add('stale');
  delete document.body.dataset.episode;
  $('detail-title').textContent = `Episode ${episode} · ${row.operator} · ${row.steps} steps (loading…)`;
  $('quality-reason').textContent = row.quality_reason ? `quality: ${row.quality_reason}` : '';
  $('flag-reason').value = row.reason || '';
  $('flag-error').textContent = '';
  drawStrip();
  let data;
  try {
    data = await api(`/api/episode/${episode}`);
  } catch (e) {
    if (pick !== picks) return;
    $('detail-title').textContent = `Episode ${episode} could not be loaded`;
    document.body.dataset.episodeError = String(episode);
    pageError(`Could not load episode ${episode}: ${e.message}`);
    return;
  }
  if (pick !== picks) return;
  pageError('');
  $('detail-title').textContent = `Episode ${episode} · ${row.operator} · ${row.steps} steps`;
  state.m = data.m;
  if (view && data.poses) {
    const raw = Uint8Array.from(atob(data.poses), (ch) => ch.charCodeAt(0));
    const all = new Float32Array(raw.buffer);
    const size = data.nbody * 7;
    const clip = [];
    for (let t = 0; t < all.length / size; t++) clip.push(all.subarray(t * size, (t + 1) * size));
    $('view').classList.remove('stale');
    player.load([clip], 20);
  } else {
    drawStrip();
  }
  delete document.body.dataset.episodeError;
  document.body.dataset.episode = String(episode);
}

async function setFlag(flagged) {
  if (state.current === null) return;
  $('flag-error').textContent = '';
  try {
    await api('/api/flag', { episode: state.current, flagged, reason: $('flag-reason').value });
  } catch (e) {
    $('flag-error').textContent = e.message;
    if (e.status !== 400) pageError(`Could not change the flag: ${e.message}`);
    return;
  }
  if (await refreshOrSay()) pageError('');
}

async function exportSelection() {
  $('export-result').textContent = 'writing…';
  $('export-result').dataset.done = 'pending';
  try {
    const r = await api('/api/export', {
      format: $('export-format').value, mask_key: $('mask-key').value,
    });
    $('export-result').textContent = `kept ${r.kept}, dropped ${r.dropped}: ${r.demos}`
      + (r.export ? `; exported to ${r.export}` : '');
    $('export-result').dataset.done = 'true';
    pageError('');
  } catch (e) {
    $('export-result').textContent = 'nothing was written';
    $('export-result').dataset.done = 'error';
    pageError(`Export refused: ${e.message}`);
  }
}

async function main() {
  for (const th of document.querySelectorAll('#episodes th')) {
    th.addEventListener('click', () => {
      state.sortDir = state.sortKey === th.dataset.key && state.sortDir === 'asc' ? 'desc' : 'asc';
      state.sortKey = th.dataset.key;
      renderTable();
    });
  }
  $('flag-form').addEventListener('submit', (e) => { e.preventDefault(); setFlag(true); });
  $('unflag-btn').addEventListener('click', () => setFlag(false));
  $('export-btn').addEventListener('click', exportSelection);
  $('play').addEventListener('click', () => player && player.toggle());
  $('scrub').addEventListener('input', () => player && player.seek(Number($('scrub').value)));
  const scene = await api('/api/scene');
  if (scene.scene) {
    view = new View($('view'));
    view.build(scene.scene);
    player = new Player(view, onPlayer);
  } else {
    $('view').hidden = true;
    $('no-view').hidden = false;
    $('no-view').textContent = scene.why;
  }
  await refresh();
  document.body.dataset.ready = 'true';
}

main().catch((e) => {
  pageError(`The review could not start: ${e.message}`);
  document.body.dataset.ready = 'error';
});
