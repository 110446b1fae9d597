// The experimenter's dashboard: polls /admin/api/state every second and keeps one row per
// operator, updating its cells in place (a focused button, a ticked box survive the update);
// what changed is announced in #announce (polite), never the clock. The buttons POST the
// actions of web/admin.py (link, pause/resume, end, remove), one operator or the selected.
const $ = (id) => document.getElementById(id);
const POLL_MS = 1000;
const rows = new Map();  // name -> { tr, cells, buttons, check }
const linkItems = new Map();  // name -> <li>
const selected = new Set();
let last = null;  // the previous poll's operators, by name (what changed is announced)
let live = null;

function text(el, value) {
  const v = String(value);
  if (el.textContent !== v) el.textContent = v;
}

function data(el, key, value) {
  const v = String(value);
  if (el.dataset[key] !== v) el.dataset[key] = v;
}

function announce(messages) {
  if (messages.length) $('announce').textContent = messages.join('. ') + '.';
}

async function post(name, action, create = false) {
  const path = `/admin/api/operators/${encodeURIComponent(name)}/${action}${create ? '?create=1' : ''}`;
  let r;
  try {
    r = await fetch(path, { method: 'POST' });
  } catch (e) {
    throw new Error('the server cannot be reached: is `elicit-jax serve` still running?');
  }
  const raw = await r.text();
  let body = null;
  try { body = JSON.parse(raw); } catch (e) { body = null; }
  if (r.ok && body) return body;
  const said = (body && body.error) || raw.trim().split('\n')[0] || r.statusText;
  const err = new Error(r.status === 403 ? `refused (${said}): open the dashboard URL the server printed again` : said);
  err.status = r.status;
  err.isNew = Boolean(body && body.new);
  throw err;
}

const CONFIRM = {
  end: (n) => `End ${n}'s session? They cannot give more demonstrations until resumed.`,
  remove: (n) => `Remove ${n} from the study? Their session is moved to .removed/ (nothing is deleted) and left out of the merged download.`,
};

function said(name, action, body) {
  if (action !== 'remove') return `${name}: ${body.status}`;
  return `${name} removed${body.moved_to ? `: their session was moved to ${body.moved_to}` : ''}`;
}

async function act(name, action) {
  if (CONFIRM[action] && !window.confirm(CONFIRM[action](name))) return;
  try {
    $('action-out').textContent = said(name, action, await post(name, action));
  } catch (e) {
    $('action-out').textContent = `${name}: ${e.message}`;
  }
  poll();
}

function existing(name) {
  const folded = name.toLowerCase();
  return [...rows.keys()].find((n) => n.toLowerCase() === folded);
}

async function issueLink(typed) {
  const name = existing(typed) || typed;
  const create = !existing(typed);
  if (create && !window.confirm(`"${typed}" is not an operator yet. Create a new operator with this name?`)) {
    $('action-out').textContent = `no operator created (${typed})`;
    return;
  }
  try {
    const body = await post(name, 'link', create);
    const url = new URL(body.link, location.href).href;
    $('link-out').textContent = url;
    $('link-out').dataset.name = body.name;
    $('action-out').textContent = `a new link for ${body.name}: their old one stops working`;
  } catch (e) {
    $('link-out').textContent = String(e.message);
  }
  poll();
}

async function copy(url, name) {
  try {
    await navigator.clipboard.writeText(url);
  } catch (e) {  // no clipboard permission: select the link, the browser's own copy
    const range = document.createRange();
    range.selectNodeContents(linkItems.get(name).querySelector('code'));
    getSelection().removeAllRanges();
    getSelection().addRange(range);
    if (!document.execCommand('copy')) {
      $('action-out').textContent = `${name}'s link is selected: press Ctrl+C to copy it`;
      return;
    }
  }
  $('action-out').textContent = `${name}'s link copied`;
}

function renderLinks(links) {
  const want = new Set(links.map((l) => l.name));
  for (const [name, li] of linkItems) if (!want.has(name)) { li.remove(); linkItems.delete(name); }
  let prev = null;
  for (const { name, link } of links) {
    const url = new URL(link, location.href).href;
    let li = linkItems.get(name);
    if (!li) {
      li = document.createElement('li');
      li.dataset.name = name;
      li.append(document.createElement('b'), document.createElement('code'));
      const b = document.createElement('button');
      b.type = 'button';
      b.textContent = 'Copy';
      b.dataset.action = 'copy';
      b.setAttribute('aria-label', `copy ${name}'s link`);
      b.onclick = () => copy(li.dataset.url, name);
      li.append(b);
      linkItems.set(name, li);
    }
    text(li.firstChild, name);
    text(li.querySelector('code'), url);
    data(li, 'url', url);
    const at = prev ? prev.nextSibling : $('links').firstChild;
    if (at !== li) $('links').insertBefore(li, at);
    prev = li;
  }
}

function cell(tr, cls) {
  const td = document.createElement('td');
  if (cls) td.className = cls;
  tr.appendChild(td);
  return td;
}

function makeRow(name) {
  const tr = document.createElement('tr');
  tr.dataset.name = name;
  const check = document.createElement('input');
  check.type = 'checkbox';
  check.dataset.name = name;
  check.setAttribute('aria-label', `select ${name}`);
  check.onchange = () => { if (check.checked) selected.add(name); else selected.delete(name); updateBulk(); };
  cell(tr, 'select').appendChild(check);
  const cells = {};
  for (const k of ['name', 'status', 'page', 'screen', 'episode']) cells[k] = cell(tr);
  for (const k of ['accepted', 'rejected', 'failed']) cells[k] = cell(tr, 'num');
  cells.verdict = cell(tr);
  text(cells.name, name);
  const td = cell(tr, 'actions');
  const buttons = {};
  for (const action of ['link', 'pause', 'resume', 'end', 'remove']) {
    const b = document.createElement('button');
    b.type = 'button';
    b.textContent = action;
    b.dataset.action = action;
    b.setAttribute('aria-label', `${action} ${name}`);
    b.onclick = () => (action === 'link' ? issueLink(name) : act(name, action));
    td.appendChild(b);
    buttons[action] = b;
  }
  const a = document.createElement('a');
  a.href = `/admin/download/${encodeURIComponent(name)}.parquet`;
  a.download = `${name}-demos.parquet`;
  a.textContent = 'download';
  td.appendChild(a);
  buttons.download = a;
  return { tr, cells, buttons, check };
}

function show(r, key, visible, instead) {
  const b = r.buttons[key];
  if (b.hidden === !visible) return;
  const hadFocus = document.activeElement === b;
  b.hidden = !visible;
  if (hadFocus && instead && !r.buttons[instead].hidden) r.buttons[instead].focus();
}

function update(r, op) {
  const { tr, cells } = r;
  const c = op.counts;
  data(tr, 'status', op.status);
  data(tr, 'screen', op.screen);
  text(cells.status, op.status);
  text(cells.page, op.page ? 'here' : 'away');
  data(cells.page, 'page', op.page);
  text(cells.screen, op.screen + (op.state === 'running' ? ' (recording)' : ''));
  const where = [op.episode + 1, op.kind, op.step ? `step ${op.step}` : ''].filter(Boolean);
  text(cells.episode, op.episode >= 0 ? where.join(' · ') : '–');
  text(cells.accepted, c ? `${c.accepted} of ${c.wanted}` : '–');
  data(cells.accepted, 'accepted', c ? c.accepted : 0);
  text(cells.rejected, c ? c.rejected : '–');
  text(cells.failed, c ? c.failed : '–');
  text(cells.verdict, op.last_verdict || '–');
  // what appears first, then what goes: a focused button that goes hands focus on
  const visible = { pause: op.status === 'active', resume: op.status !== 'active', end: op.status !== 'ended' };
  for (const k of Object.keys(visible)) if (visible[k]) show(r, k, true);
  show(r, 'pause', visible.pause, 'resume');
  show(r, 'resume', visible.resume, 'pause');
  show(r, 'end', visible.end, 'resume');
  show(r, 'download', Boolean(c && c.accepted > 0));
}

// What changed since the last poll, in words (the clock and the step counter are not news).
function changes(ops) {
  const now = new Map(ops.map((op) => [op.name, op]));
  if (last === null) return [];
  const out = [];
  for (const name of last.keys()) if (!now.has(name)) out.push(`${name} is no longer listed`);
  for (const op of ops) {
    const was = last.get(op.name);
    if (!was) { out.push(`new operator ${op.name}`); continue; }
    if (was.status !== op.status) out.push(`${op.name}: ${op.status}`);
    if (was.page !== op.page) out.push(`${op.name}'s page is ${op.page ? 'here' : 'away'}`);
    const c = op.counts || {}, w = was.counts || {};
    if (c.accepted !== w.accepted && c.accepted !== undefined) out.push(`${op.name}: ${c.accepted} of ${c.wanted} accepted`);
    if (c.rejected !== w.rejected && c.rejected !== undefined) out.push(`${op.name}: ${c.rejected} rejected`);
    if (c.failed !== w.failed && c.failed !== undefined) out.push(`${op.name}: ${c.failed} failed`);
  }
  return out;
}

function updateBulk() {
  for (const name of [...selected]) if (!rows.has(name)) selected.delete(name);
  const n = selected.size;
  text($('bulk-count'), n ? `${n} selected` : 'none selected');
  for (const id of ['bulk-pause', 'bulk-end', 'bulk-remove']) $(id).disabled = n === 0;
  const all = $('select-all');
  all.checked = n > 0 && n === rows.size;
  all.indeterminate = n > 0 && n < rows.size;
}

async function bulk(action) {
  const names = [...selected].sort();
  if (!names.length) return;
  const verb = { pause: 'Pause', end: 'End', remove: 'Remove' }[action];
  const what = action === 'remove'
    ? 'Their sessions are moved to .removed/ (nothing is deleted) and left out of the merged download.'
    : action === 'end' ? 'They cannot give more demonstrations until resumed.' : 'Their pages are closed until you resume them.';
  if (!window.confirm(`${verb} ${names.length} operator${names.length === 1 ? '' : 's'} (${names.join(', ')})? ${what}`)) return;
  const done = [], failed = [];
  for (const name of names) {
    try {
      await post(name, action);
      done.push(name);
      if (action === 'remove') selected.delete(name);
    } catch (e) {
      failed.push(`${name} (${e.message})`);
    }
  }
  const past = { pause: 'paused', end: 'ended', remove: 'removed' }[action];
  $('action-out').textContent = [done.length ? `${past}: ${done.join(', ')}` : '', failed.length ? `not ${past}: ${failed.join('; ')}` : '']
    .filter(Boolean).join(' · ');
  await poll();
}

let timer = null;
async function poll() {
  clearTimeout(timer);
  try {
    const r = await fetch('/admin/api/state', { cache: 'no-store' });
    if (!r.ok) throw new Error(r.status === 403 ? 'refused: open the dashboard URL the server printed again' : `the server answered ${r.status}`);
    const st = await r.json();
    text($('about'), `${st.task} · ${st.mode} · ${st.wanted} demonstration${st.wanted === 1 ? '' : 's'} wanted per operator · ${st.sessions}`);
    const names = new Set(st.operators.map((op) => op.name));
    for (const [name, row] of rows) if (!names.has(name)) { row.tr.remove(); rows.delete(name); }
    const body = $('operators').tBodies[0];
    let prev = null;
    for (const op of st.operators) {
      let row = rows.get(op.name);
      if (!row) { row = makeRow(op.name); rows.set(op.name, row); }
      update(row, op);
      const at = prev ? prev.nextSibling : body.firstChild;
      if (at !== row.tr) body.insertBefore(row.tr, at);  // only new rows move: focus stays
      prev = row.tr;
    }
    $('empty').hidden = st.operators.length > 0;
    renderLinks(st.links || []);
    updateBulk();
    const news = changes(st.operators);
    if (live === false) news.unshift('updating again');
    announce(news);
    last = new Map(st.operators.map((op) => [op.name, op]));
    live = true;
    document.body.dataset.live = 'yes';
    text($('live'), `live · ${new Date().toLocaleTimeString()}`);
  } catch (e) {
    if (live !== false) announce([`the dashboard is not updating: ${e.message}`]);
    live = false;
    document.body.dataset.live = 'no';
    text($('live'), `not updating: ${e.message}`);
  }
  timer = setTimeout(poll, POLL_MS);
}

$('link-form').addEventListener('submit', (e) => {
  e.preventDefault();
  issueLink($('link-name').value.trim());
});
$('select-all').addEventListener('change', () => {
  const on = $('select-all').checked;
  for (const [name, row] of rows) {
    row.check.checked = on;
    if (on) selected.add(name); else selected.delete(name);
  }
  updateBulk();
});
for (const action of ['pause', 'end', 'remove']) $(`bulk-${action}`).addEventListener('click', () => bulk(action));
poll();
