// The experimenter's dashboard: polls /admin/api/state every second and draws one row per
// operator; the buttons POST the actions (link, pause/resume, end, remove) of web/admin.py.
const $ = (id) => document.getElementById(id);
const POLL_MS = 1000;

function cell(tr, text, cls) {
  const td = document.createElement('td');
  td.textContent = text;
  if (cls) td.className = cls;
  tr.appendChild(td);
  return td;
}

function button(td, label, onClick) {
  const b = document.createElement('button');
  b.type = 'button';
  b.textContent = label;
  b.dataset.action = label;
  b.onclick = onClick;
  td.appendChild(b);
}

async function post(name, action) {
  const r = await fetch(`/admin/api/operators/${encodeURIComponent(name)}/${action}`, { method: 'POST' });
  const body = await r.json();
  if (!r.ok) throw new Error(body.error || `${action} failed (${r.status})`);
  return body;
}

async function act(name, action, confirmText) {
  if (confirmText && !window.confirm(confirmText)) return;
  try {
    const body = await post(name, action);
    $('action-out').textContent = action === 'remove'
      ? `${name} removed${body.moved_to ? `: their session was moved to ${body.moved_to}` : ''}`
      : `${name}: ${body.status}`;
  } catch (e) {
    $('action-out').textContent = String(e.message);
  }
  poll();
}

async function issueLink(name) {
  try {
    const body = await post(name, 'link');
    const url = new URL(body.link, location.href).href;
    $('link-out').textContent = url;
    $('link-out').dataset.name = name;
  } catch (e) {
    $('link-out').textContent = String(e.message);
  }
  poll();
}

function row(op) {
  const tr = document.createElement('tr');
  tr.dataset.name = op.name;
  tr.dataset.status = op.status;
  tr.dataset.screen = op.screen;
  const c = op.counts;
  cell(tr, op.name);
  cell(tr, op.status);
  cell(tr, op.page ? 'here' : 'away').dataset.page = String(op.page);
  cell(tr, op.screen + (op.state === 'running' ? ' (recording)' : ''));
  const where = [op.episode + 1, op.kind, op.step ? `step ${op.step}` : ''].filter(Boolean);
  cell(tr, op.episode >= 0 ? where.join(' · ') : '–');
  cell(tr, c ? `${c.accepted} of ${c.wanted}` : '–', 'num').dataset.accepted = c ? c.accepted : 0;
  cell(tr, c ? c.rejected : '–', 'num');
  cell(tr, c ? c.failed : '–', 'num');
  cell(tr, op.last_verdict || '–');
  const td = cell(tr, '', 'actions');
  button(td, 'link', () => issueLink(op.name));
  if (op.status === 'active') button(td, 'pause', () => act(op.name, 'pause'));
  else button(td, 'resume', () => act(op.name, 'resume'));
  if (op.status !== 'ended') button(td, 'end', () => act(op.name, 'end', `End ${op.name}'s session? They cannot give more demonstrations until resumed.`));
  button(td, 'remove', () => act(op.name, 'remove', `Remove ${op.name} from the study? Their session is moved to .removed/ (nothing is deleted) and left out of the merged download.`));
  if (c && c.accepted > 0) {
    const a = document.createElement('a');
    a.href = `/admin/download/${encodeURIComponent(op.name)}.parquet`;
    a.download = `${op.name}-demos.parquet`;
    a.textContent = 'download';
    td.appendChild(a);
  }
  return tr;
}

let timer = null;
async function poll() {
  clearTimeout(timer);
  try {
    const r = await fetch('/admin/api/state', { cache: 'no-store' });
    if (!r.ok) throw new Error(`the server answered ${r.status}`);
    const st = await r.json();
    $('about').textContent = `${st.task} · ${st.mode} · ${st.wanted} demonstration${st.wanted === 1 ? '' : 's'} wanted per operator · ${st.sessions}`;
    const body = document.createElement('tbody');
    for (const op of st.operators) body.appendChild(row(op));
    $('operators').replaceChild(body, $('operators').tBodies[0]);
    $('empty').hidden = st.operators.length > 0;
    document.body.dataset.live = 'yes';
    $('live').textContent = `live · ${new Date().toLocaleTimeString()}`;
  } catch (e) {
    document.body.dataset.live = 'no';
    $('live').textContent = `not updating: ${e.message}`;
  }
  timer = setTimeout(poll, POLL_MS);
}

$('link-form').addEventListener('submit', (e) => {
  e.preventDefault();
  issueLink($('link-name').value.trim());
});
poll();
