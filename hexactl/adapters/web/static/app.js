// hexactl dashboard: the WebSocket link to the dashboard server, the header, the
// telemetry readouts and the wiring of the 3D view, the plots, the control panels and
// the loop's events.
import { View3D, strokeMargin } from './view3d.js';
import { History, Plots } from './plots.js';
import { setupControls, fmt, fmtPose, AXES } from './controls.js';
import { setupEvents, isWarning } from './events.js';
import { groupFaults, faultLine, faultAdvice } from './faults.js';

const $ = (id) => document.getElementById(id);
const RECONNECT_MS = 1000;
const LATENCY_RING = 2000;
const STALE_MS = 2000;        // no telemetry for longer, or this far behind it: nothing on the page is shown as current
const REPORT_SILENT_S = 1.0;   // a record whose loop.report_age_s is over this is a stopped loop's last (control/results.py's REPORT_SILENT_S; tests/web/test_page_constants.py keeps them equal)
const OTHER_CONTROLLER_WINDOW_S = 1.0;  // another controller heard this recently drives the actuators (control/results.py's, likewise)
const TICK_MS = 250;          // the staleness check and the "no data for N s" count
// Telemetry handled between two acknowledgements: the server sends at most
// TELEMETRY_WINDOW (16, adapters/web/bridge.py) unacknowledged, so that a page slower than
// the records falls no further behind than that. Below the window, or the page stalls.
const ACK_EVERY = 8;
// Also an acknowledgement at least this often while telemetry is handled: how far behind
// the page is, is timed from its acknowledgements (acksAwaited), so a page slower than the
// records learns it soon, not after ACK_EVERY of its slow records.
const ACK_INTERVAL_MS = 250;
const ACKS_AWAITED_MAX = 64;  // more awaited means the server is not answering them: the oldest is what counts
// The dashboard host's clock, from the acknowledgements' round trips: the offset of the
// quickest of the last CLOCK_SAMPLES (the one least held up on the way, NTP's rule).
const CLOCK_SAMPLES = 32;
const pageStartedAt = performance.now();

const state = {
  ws: null,
  wsOpen: false,
  wsReason: 'connecting to the dashboard server…',
  link: null,               // last `link` message
  record: null,
  geometry: null,
  ghost: null,
  nextId: 1,
  pending: new Map(),       // id -> {cmd, done, timer, sentAt}
  // How long a command's reply is waited for: the dashboard's own (its --timeout), from its
  // `hello`, the first message on each connection. The dashboard gives each command that
  // long from when it reads it and answers it `expired` if it could not send it in time,
  // so nothing the page has given up on is carried out later. null until the hello.
  commandTimeoutMs: null,
  newRecord: false,
  drawInfo: null,           // {age_ms, sent_ms} of the newest record, until drawn
  lastTelemetryAt: 0,
  unacknowledged: 0,        // telemetry handled on this WebSocket since the last acknowledgement
  lastAckAt: 0,
  acksAwaited: [],          // {n, at, wall}: acknowledgements sent whose `acked` has not come back, oldest first
  clockSamples: [],         // {roundTrip, offset}, ms: the dashboard host's clock minus the page's, per `acked`
  clockOffset: null,        // ms to add to the page's Date.now() for the dashboard host's; null until measured
  latencies: new Array(LATENCY_RING),
  latencyCount: 0,
  loss: null,               // what the page shows as lost (dataLoss()); null while live
};

// The E-stop's confirmation: a press is confirmed only by an ok reply to an `estop`.
const estopState = {
  presses: 0,
  awaiting: 0,              // presses sent whose reply has not come
  warning: false,           // "E-STOP NOT CONFIRMED" on screen
  seqAtPress: 0,            // the newest event number seen when the last press went: an estop event after it is one in force
  events: [],               // {press, what, detail, t}: for the tests and tools (window.hexactlDashboard)
};

// ---------------- messages log ----------------
const messagesEl = $('messages');
const MERGE_MS = 2000;      // the same message again within this is one line, counted; later, a line of its own
function logMessage(kind, cmd, code, message) {
  const text = `${cmd ? `${cmd}: ` : ''}${code ?? ''}|${message ?? ''}`;
  const first = messagesEl.firstElementChild;
  const at = Date.now();
  const now = new Date(at).toLocaleTimeString();
  // Repeats of a burst merge; each E-stop is a line of its own, with its time.
  if (cmd !== 'estop' && first && first.dataset.key === text && at - Number(first.dataset.last) < MERGE_MS) {
    const count = Number(first.dataset.count || 1) + 1;
    first.dataset.count = String(count);
    first.dataset.last = String(at);
    first.querySelector('.count').textContent = ` ×${count} (last ${now})`;
    return;
  }
  const li = document.createElement('li');
  li.className = `${kind} fresh`;
  li.dataset.key = text;
  li.dataset.last = String(at);
  const time = document.createElement('span'); time.className = 'time'; time.textContent = `${now} `;
  const c = document.createElement('span'); c.className = 'code'; c.textContent = `${cmd ? `${cmd} ` : ''}${code ?? ''} `;
  const m = document.createElement('span'); m.className = 'msg'; m.textContent = message ?? '';
  const n = document.createElement('span'); n.className = 'count muted';
  li.append(time, c, m, n);
  messagesEl.prepend(li);
  while (messagesEl.children.length > 200) messagesEl.lastElementChild.remove();
}
$('messages-clear').addEventListener('click', () => { messagesEl.textContent = ''; });

// ---------------- commands ----------------
function failure(code, message) { return { ok: false, error: { code, message } }; }

// The commands that can move or energise the platform: never sent while the page has no
// live data, whose panel cannot show what they would do (a jog's zero-velocity release stops).
const MOVING_CMDS = new Set(['enable', 'move', 'jog', 'play', 'resume', 'wave', 'stream_open', 'leg_lock',
  'load_calibration', 'rollback_calibration']);
const moves = (cmd, fields) => MOVING_CMDS.has(cmd)
  && !(cmd === 'jog' && Array.isArray(fields.velocity) && fields.velocity.every((v) => v === 0));

/** Send one API command; resolves with its reply (never rejects). Failed replies are logged. */
function send(cmd, fields = {}) {
  return new Promise((resolve) => {
    const done = (reply) => {
      if (!reply || typeof reply !== 'object') reply = failure('bad_reply', 'the server sent no usable reply');
      if (reply.ok === false) logMessage('error', cmd, reply.error?.code ?? 'error', reply.error?.message ?? '');
      resolve(reply);
    };
    const ws = state.ws;
    if (!ws || ws.readyState !== WebSocket.OPEN) {
      done(failure('unavailable', `not connected to the dashboard server: ${cmd} not sent`));
      return;
    }
    const loss = dataLoss(performance.now());
    if (loss !== null && moves(cmd, fields)) {
      done(failure('no_live_data', `not sent: the page has no live data (${LOSS_SHORT[loss]}), so it cannot show `
        + 'what this would move; do it once live data return (E-STOP, Stop and Abort always go)'));
      return;
    }
    const id = state.nextId++;
    const pending = { cmd, done, timer: null, sentAt: performance.now() };
    state.pending.set(id, pending);
    armTimeout(id, pending);
    try {
      // `at`: when the operator's action made it, on the page's clock: the dashboard counts
      // its time to live from then, so one held up on the way expires instead of running late
      ws.send(JSON.stringify({ ...fields, type: 'command', id, cmd, at: pending.sentAt }));
    } catch (e) {
      clearTimeout(pending.timer);
      state.pending.delete(id);
      done(failure('unavailable', `could not send: ${e && e.message ? e.message : e}`));
    }
  });
}

/** Give up on command `id` the dashboard's command timeout after it was sent (once the hello has said it). */
function armTimeout(id, pending) {
  if (state.commandTimeoutMs === null || pending.timer !== null) return;
  const timeoutMs = state.commandTimeoutMs;
  pending.timer = setTimeout(() => {
    if (state.pending.get(id) !== pending) return;
    state.pending.delete(id);
    pending.done(failure('timeout', `no reply within ${timeoutMs / 1000} s`));
  }, Math.max(0, pending.sentAt + timeoutMs - performance.now()));
}

function failPending(reason) {
  for (const [id, p] of state.pending) {
    clearTimeout(p.timer);
    state.pending.delete(id);
    p.done(failure('unavailable', reason));
  }
}

// ---------------- E-stop ----------------
const estopButton = $('estop');
const estopWarning = $('estop-warning');

function estopEvent(press, what, detail = '') {
  estopState.events.push({ press, what, detail, t: performance.now() });
  if (estopState.events.length > 200) estopState.events.splice(0, estopState.events.length - 200);
}

/** "E-STOP NOT CONFIRMED — use the hardware E-stop" until an ok reply to an estop. */
function showEstopWarning(press, detail) {
  setText('estop-warning-detail', detail);
  if (!estopState.warning) {
    estopState.warning = true;
    estopWarning.hidden = false;
    estopButton.classList.add('unconfirmed');
    updateDismiss();
  }
  estopEvent(press, 'warning', detail);
}

function clearEstopWarning(press, why) {
  if (!estopState.warning) return;
  estopState.warning = false;
  estopWarning.hidden = true;
  estopButton.classList.remove('unconfirmed');
  estopEvent(press, 'cleared', why);
}

function updateDismiss() {
  // dismissing without a confirmation is offered only once live data show the platform again
  const button = $('estop-warning-dismiss');
  const live = state.loss === null && state.record !== null;
  button.disabled = !live;
  button.title = live ? 'The page has live data again: check the state shown, then dismiss'
    : 'Available once live data return';
}
$('estop-warning-dismiss').addEventListener('click', () => clearEstopWarning(0, 'dismissed by the operator'));

const LOSS_SHORT = {
  server: 'the page has no connection to the dashboard server',
  service: 'the dashboard server has no telemetry from the hexactl service',
  telemetry: 'no telemetry has reached the page',
  loop: "the service's control loop has sent nothing",
  late: 'the page is handling the telemetry more slowly than it comes',
  starting: 'no telemetry has reached the page yet',
};
/** The E-STOP warning's detail for a press awaiting its reply while the page has lost `loss`. */
function notConfirmedYet(loss) {
  const doubt = loss === 'late' ? 'its reply waits behind the telemetry the page has not handled yet'
    : 'the service may not be running';
  return `Sent, no confirmation yet: ${LOSS_SHORT[loss]}, so ${doubt}.`;
}

/** `pressed`: what sent it, as the Move panel says why Go was withdrawn. */
function estop(pressed = 'E-STOP') {
  // first on the wire: nothing the page does for the display comes before the request
  const replied = state.wsOpen ? send('estop') : null;
  const loss = dataLoss(performance.now());
  const press = ++estopState.presses;
  estopState.seqAtPress = newestEventSeq(state.record);
  estopEvent(press, 'pressed', loss ?? 'live');
  if (replied) estopEvent(press, 'sent');
  controls.releaseJog(false);
  controls.withdrawnBy(pressed);
  estopButton.classList.remove('sent');
  void estopButton.offsetWidth;   // restart the flash animation
  estopButton.classList.add('sent');
  if (!replied) {
    logMessage('error', 'estop', 'NOT SENT', 'not connected to the dashboard server: use the hardware E-stop');
    showEstopWarning(press, 'NOT SENT: the page has no connection to the dashboard server, so no button can reach the service.');
    return;
  }
  // no live data: whether the service gets it is unknown, so say so now, not after the request's timeout
  if (loss !== null) showEstopWarning(press, notConfirmedYet(loss));
  estopState.awaiting += 1;
  replied.then((reply) => {
    estopState.awaiting -= 1;
    if (reply.ok) {
      estopEvent(press, 'reply-ok');
      logMessage('info', 'estop', 'ok', reply.message ?? 'emergency stop latched');
      clearEstopWarning(press, 'confirmed by the service');
    } else {
      const code = reply.error?.code ?? 'error';
      estopEvent(press, 'reply-failed', code);
      showEstopWarning(press, `The service did not confirm it: ${code}: ${reply.error?.message ?? ''}`);
    }
  });
}
// Sent on the press, not on the release: a click needs the release over the button, and an
// operator who slid off it, or a touch screen that took the touch for a scroll, sent nothing
// (found from outside). A mouse's left press is its mousedown, which comes for a press while
// another button is held too (a pointerdown does not); a touch's or a pen's is its
// pointerdown, whose default (the mouse events that would follow) is prevented. A click the
// keyboard makes (Enter or Space: detail 0) sends it too, once however long the key is held;
// a pointer's click follows the press that already sent it.
estopButton.addEventListener('mousedown', (ev) => { if (ev.button === 0) estop(); });
estopButton.addEventListener('pointerdown', (ev) => {
  if (ev.pointerType !== 'mouse' && ev.button === 0) { ev.preventDefault(); estop(); }
});
estopButton.addEventListener('keydown', (ev) => { if (ev.repeat) ev.preventDefault(); });
estopButton.addEventListener('click', (ev) => { if (ev.detail === 0) estop(); });

function newestEventSeq(r) {
  const events = Array.isArray(r?.events) ? r.events : [];
  return Math.max(0, ...events.map((e) => (e && Number.isSafeInteger(e.seq) ? e.seq : 0)));
}

/**
 * A warning on screen is answered by the records too: the controller in estop, by an estop
 * event after the press (a queued E-stop the loop carried out once it ran again, or another
 * client's), is the E-stop in force, said as such: the banner's "not confirmed" would
 * contradict the state shown beside it.
 */
function estopSeenInForce(r) {
  if (!estopState.warning || r.state !== 'estop' || !Array.isArray(r.events)) return;
  const latched = r.events.find((e) => e && e.code === 'estop' && Number.isSafeInteger(e.seq) && e.seq > estopState.seqAtPress);
  if (!latched) return;
  const by = latched.sender ? ` (sent by ${latched.sender})` : '';
  logMessage('info', 'estop', 'in force', `the controller is in estop: event ${latched.seq}, ${latched.message}${by}`);
  clearEstopWarning(estopState.presses, `in force: event ${latched.seq}`);
}
window.addEventListener('keydown', (ev) => {
  if (ev.key === 'Escape' || ev.code === 'Escape') {
    ev.preventDefault();
    if (!ev.repeat) estop('E-STOP (Escape)');
  }
}, true);

// ---------------- 3D view, plots, controls ----------------
const view = new View3D($('view3d'));
const history = new History();
const plots = new Plots(history, { pose: $('plot-pose'), legs: $('plot-legs'), loop: $('plot-loop') });
const controls = setupControls({
  send,
  record: () => state.record,
  noLiveData: () => { const loss = dataLoss(performance.now()); return loss === null ? null : LOSS_SHORT[loss]; },
  setGhost: (goal) => { state.ghost = Array.isArray(goal) ? goal.slice() : null; state.newRecord = true; schedule(); },
});

const UNIT = ['mm', 'mm', 'mm', '°', '°', '°'];
function plotTitles() {
  const a = Number($('plot-axis').value);
  $('plot-pose-title').textContent = `pose ${AXES[a]}: commanded vs measured (${UNIT[a] === '°' ? 'deg' : 'mm'}, relative to the zero posture)`;
  $('plot-leg-title').textContent = `leg ${$('plot-leg').value}: set-point vs feedback (sensor mm)`;
}
$('plot-axis').addEventListener('change', () => { plotTitles(); plots.setAxis(Number($('plot-axis').value)); });
$('plot-leg').addEventListener('change', () => { plotTitles(); plots.setLeg(Number($('plot-leg').value) - 1); });
$('plot-window').addEventListener('change', () => plots.setWindow(Number($('plot-window').value)));
$('plot-pause').addEventListener('click', () => {
  const paused = !plots.paused;
  plots.setPaused(paused);
  $('plot-pause').setAttribute('aria-pressed', String(paused));
  $('plot-pause').textContent = paused ? 'Resume' : 'Pause';
});
$('plot-export').addEventListener('click', () => {
  const blob = new Blob([history.toCSV()], { type: 'text/csv' });
  const url = URL.createObjectURL(blob);
  const a = document.createElement('a');
  const d = new Date();
  a.href = url;
  a.download = `hexactl-dashboard-${d.toISOString().replace(/[:.]/g, '-').slice(0, 19)}.csv`;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10000);
});
plotTitles();
const eventsPanel = setupEvents((after) => send('events', { after }));

// ---------------- header and readouts ----------------
const shown = {};
function setText(id, text) {
  if (shown[id] === text) return;
  shown[id] = text;
  $(id).textContent = text;
}
function setPill(id, value, prefix) {
  setText(id, value ?? '–');
  const el = $(id);
  const cls = `pill ${prefix}-${value ?? 'none'}`;
  if (el.className !== cls) el.className = cls;
}

function updateConnection() {
  const connected = state.wsOpen && state.link !== null && state.link.connected === true;
  let text;
  if (!state.wsOpen) text = `disconnected: ${state.wsReason}`;
  else if (state.link === null) text = 'disconnected: waiting for the link to the hexactl service…';
  else if (!state.link.connected) text = `disconnected: the hexactl service is unreachable${state.link.message ? ` (${state.link.message})` : ''}; retrying`;
  else text = 'connected';
  setText('connection', text);
  $('connection').title = state.link?.message ?? text;
  document.body.dataset.connected = connected ? 'true' : 'false';
}

function updateFaults(faults, controllerState) {
  const groups = groupFaults(faults);
  const advice = groups.length ? faultAdvice(controllerState) : '';
  const key = JSON.stringify([groups, advice]);
  if (shown.faults === key) return;
  shown.faults = key;
  const ul = $('faults');
  ul.textContent = '';
  for (const group of groups) {
    const li = document.createElement('li');
    const b = document.createElement('b');
    b.textContent = group.code;
    li.append(b, document.createTextNode(` ${faultLine(group)}`));
    li.title = group.all.join('\n');
    ul.append(li);
  }
  if (advice) {
    const li = document.createElement('li');
    li.className = 'advice';
    li.textContent = advice;
    ul.append(li);
  }
}

// Another controller heard on the bus (telemetry's other_controller): it drives these actuators too.
function updateOtherController(heard) {
  const valid = heard !== null && typeof heard === 'object' && typeof heard.age_s === 'number';
  const el = $('other-controller');
  el.hidden = !valid;
  if (!valid) return;
  const now = heard.age_s <= OTHER_CONTROLLER_WINDOW_S;
  el.classList.toggle('now', now);
  setText('other-controller', now
    ? `ANOTHER CONTROLLER on the bus: ${heard.frame} heard ${fmt(heard.age_s, 2)} s ago. It drives these actuators too; `
      + 'Enable is refused until it stops (candump on the CAN interface shows it).'
    : `another controller last heard on the bus ${fmt(heard.age_s, 0)} s ago (${heard.frame})`);
}

// The link to the actuators (telemetry's link), as `hexactl status` words it: muted while the bus is active,
// in red otherwise, with the link's note (silent legs, a restarted leg, the last driver error).
const BUS_STATE_TEXT = {
  active: 'CAN bus active',
  warning: 'CAN bus WARNING: error counters high, frames still get through',
  passive: 'CAN bus ERROR-PASSIVE: frames get through with errors; check the wiring, its two terminations and the bit rate before it goes bus-off',
  bus_off: 'CAN bus OFF: this controller has left the bus and sends nothing (enable says what to check)',
  down: 'CAN interface DOWN: closed or missing, nothing is sent or heard',
};
function updateLink(link) {
  const valid = link !== null && typeof link === 'object' && typeof link.bus_state === 'string';
  const el = $('link-state');
  el.hidden = !valid;
  if (!valid) return;
  const failures = Number.isInteger(link.send_failures) ? link.send_failures : 0;
  el.classList.toggle('bad', link.bus_state !== 'active');
  setText('link-state', [
    BUS_STATE_TEXT[link.bus_state] ?? `CAN bus ${link.bus_state}`,
    failures ? `${failures} send failure${failures === 1 ? '' : 's'}` : 'no send failures',
    typeof link.detail === 'string' ? link.detail : '',
  ].filter(Boolean).join('; '));
}

const poseRows = $('pose-table').tBodies[0].rows;
const legRows = $('leg-table').tBodies[0].rows;
const cellCache = new Map();
function setCell(cell, text, cls) {
  const prev = cellCache.get(cell);
  if (prev && prev[0] === text && prev[1] === cls) return;
  cellCache.set(cell, [text, cls]);
  cell.textContent = text;
  cell.className = cls ?? '';
}
function fillPoseRow(row, pose) {
  for (let i = 0; i < 6; i++) setCell(row.cells[i + 1], Array.isArray(pose) ? fmt(pose[i], i < 3 ? 2 : 3) : '–');
}

// The pose stream under way (what the loop follows and what the receiver counted), or how the last one ended.
function streamSummary(r) {
  const s = r.stream && typeof r.stream === 'object' ? r.stream : null;
  const input = r.stream_input && typeof r.stream_input === 'object' ? r.stream_input : null;
  if (s) {
    const parts = [`stream ${s.stream} from ${s.source} (${s.frame}) ${s.phase}: ${s.targets} targets`];
    if (input && input.stream === s.stream) {
      parts.push(`${input.rate_hz} Hz`);
      parts.push(`dropped ${(input.malformed ?? 0) + (input.out_of_order ?? 0) + (input.other_sender ?? 0)}`);
      parts.push(`clamped ${input.clamped ?? 0}`);
      if (input.failed) parts.push(`failed ${input.failed}`);
      if (input.loop_latency_ms) parts.push(`latency p50 ${fmt(input.loop_latency_ms.p50, 1)} ms`);
    }
    if (input && input.running === false) parts.push('INPUT STOPPED: see the service log');
    return parts.join(' · ');
  }
  const stopped = input && input.running === false ? 'stream input stopped (see the service log): restart the service to stream' : '';
  const last = r.last_stream && typeof r.last_stream === 'object' ? r.last_stream : null;
  return [last ? `last stream ${last.stream}: ${last.reason} (${last.targets} targets)` : '', stopped].filter(Boolean).join(' · ');
}

/** The tab's title says the state, so that a page among other tabs shows an E-stop or a fault. */
function tabTitle(text) {
  const title = `${text} · hexactl dashboard`;
  if (document.title !== title) document.title = title;
}

function updateReadouts(r) {
  setPill('state', r.state, 'st');
  tabTitle(String(r.state).toUpperCase());
  setPill('motion', r.motion, 'mo');
  setText('calibration-id', r.calibration_id ?? '–');
  const geomId = state.geometry?.calibration_id;
  $('calibration-id').title = geomId && r.calibration_id && geomId !== r.calibration_id
    ? `the telemetry's calibration ${r.calibration_id} differs from the drawn geometry's ${geomId}` : (state.geometry?.name ?? '');
  updateFaults(r.faults, r.state);
  updateOtherController(r.other_controller);
  updateLink(r.link);

  const loop = r.loop && typeof r.loop === 'object' ? r.loop : null;
  setText('loop-summary', loop
    ? `${fmt(loop.rate_hz, 0)} Hz · p99 ${fmt(loop.lateness_us?.p99, 0)} µs · missed ${loop.missed ?? '–'}${loop.guard_clamps ? ` · clamps ${loop.guard_clamps}` : ''}`
    : '–');

  fillPoseRow(poseRows[0], r.pose_command);
  fillPoseRow(poseRows[1], r.pose_measured);
  fillPoseRow(poseRows[2], r.goal);
  fillPoseRow(poseRows[3], r.tool_pose_command);
  const g = view.geometry;
  const lengths = view.legLengths();
  for (let i = 0; i < 6; i++) {
    const locked = r.locked_leg === i + 1 ? 'locked' : '';
    setCell(legRows[0].cells[i + 1], fmt(r.leg_setpoints?.[i], 2), locked);
    setCell(legRows[1].cells[i + 1], fmt(r.leg_feedback?.[i], 2), locked);
    const m = g && lengths ? strokeMargin(g, i, lengths[i]) : null;
    const cls = m === null ? '' : (m > 0.2 ? 'm-ok' : (m >= 0.05 ? 'm-warn' : 'm-bad'));
    setCell(legRows[2].cells[i + 1], m === null ? '–' : `${(m * 100).toFixed(1)}%`, `${cls} ${locked}`.trim());
  }
  const extra = [];
  if (typeof r.remaining_s === 'number') extra.push(`remaining ${r.remaining_s.toFixed(2)} s`);
  if (r.wave && typeof r.wave === 'object') extra.push(`wave ${r.wave.cycle ?? '?'}/${r.wave.cycles ?? '?'} ${r.wave.phase ?? ''}`);
  if (r.jog && typeof r.jog === 'object') extra.push(`jog ${r.jog.phase ?? ''}${r.jog.end ? ` to ${r.jog.end}` : ''}`);
  if (loop) extra.push(`compute p99 ${fmt(loop.compute_us?.p99, 0)} µs, cycles ${loop.cycles ?? '–'}`);
  setText('telemetry-extra', extra.join(' · '));
  setText('stream-summary', streamSummary(r));

  const hud = [`command  ${fmtPose(r.pose_command, 2)}`];
  if (Array.isArray(r.pose_measured) && Array.isArray(r.pose_command)) {
    const dp = Math.hypot(...[0, 1, 2].map((i) => (r.pose_measured[i] ?? 0) - (r.pose_command[i] ?? 0)));
    const da = Math.max(...[3, 4, 5].map((i) => Math.abs((r.pose_measured[i] ?? 0) - (r.pose_command[i] ?? 0))));
    hud.push(`measured Δ ${dp.toFixed(3)} mm, ${da.toFixed(4)} °`);
  } else {
    hud.push('measured  none');
  }
  if (Array.isArray(r.goal)) hud.push(`goal     ${fmtPose(r.goal, 2)}${typeof r.remaining_s === 'number' ? `  in ${r.remaining_s.toFixed(1)} s` : ''}`);
  if (state.ghost) hud.push(`ghost    ${fmtPose(state.ghost, 2)} (validated)`);
  if (Number.isInteger(r.locked_leg)) hud.push(`leg ${r.locked_leg} locked`);
  setText('view3d-hud', hud.join('\n'));
}

function latencyValues() {
  const n = Math.min(state.latencyCount, LATENCY_RING);
  const out = new Array(n);
  const start = state.latencyCount - n;
  for (let k = 0; k < n; k++) out[k] = state.latencies[(start + k) % LATENCY_RING];
  return out;
}

let latencyShownAt = 0;
function updateLatencySummary(now) {
  if (now - latencyShownAt < 500) return;
  latencyShownAt = now;
  const v = latencyValues().slice(-250);
  if (!v.length) { setText('latency-summary', '–'); return; }
  const sorted = v.slice().sort((a, b) => a - b);
  const p = (q) => sorted[Math.min(sorted.length - 1, Math.floor(q * sorted.length))];
  setText('latency-summary', `${p(0.5).toFixed(0)} ms · p99 ${p(0.99).toFixed(0)} ms`);
}

// ---------------- drawing: one requestAnimationFrame per change ----------------
let frameScheduled = false;
let plotTimer = null;
function schedule() {
  if (frameScheduled) return;
  frameScheduled = true;
  requestAnimationFrame(frame);
}

function frame(now) {
  frameScheduled = false;
  if (state.newRecord && state.record) {
    state.newRecord = false;
    const r = state.record;
    try {
      view.update(r, state.ghost);
      view.render();
    } catch (e) {
      // a drawing problem must not stop telemetry, plots or controls
      logMessage('error', '3D view', 'draw_failed', e && e.message ? e.message : String(e));
    }
    if (state.drawInfo) {
      const { age_ms: age, sent_ms: sent } = state.drawInfo;
      state.drawInfo = null;
      if (Number.isFinite(age) && Number.isFinite(sent) && state.clockOffset !== null) {
        state.latencies[state.latencyCount % LATENCY_RING] = age + (Date.now() + state.clockOffset - sent);
        state.latencyCount += 1;
      }
    }
    updateReadouts(r);
    controls.onRecord(r);
    eventsPanel.draw(now);
    updateLatencySummary(now);
    applyLiveness(performance.now());   // a record drawn while no data are live is not shown as current
  }
  plots.maybeRedraw(now);
  if (plots.dirty && !plots.paused && plotTimer === null) {
    plotTimer = setTimeout(() => { plotTimer = null; schedule(); }, 220);
  }
}

// ---------------- WebSocket ----------------
function handleMessage(ev) {
  let msg;
  try { msg = JSON.parse(ev.data); } catch (e) { return; }
  if (!msg || typeof msg !== 'object') return;
  switch (msg.type) {
    case 'telemetry': {
      acknowledge(msg.n);  // first: an exception below must not stop the telemetry
      const r = msg.record;
      if (!r || typeof r !== 'object') return;
      state.record = r;
      // a null age or send time (unknown) gives no latency sample rather than a wrong one
      const numOrNaN = (v) => (typeof v === 'number' ? v : NaN);
      state.drawInfo = { age_ms: numOrNaN(msg.age_ms), sent_ms: numOrNaN(msg.sent_ms) };
      state.newRecord = true;
      state.lastTelemetryAt = performance.now();
      history.push(r);
      plots.dirty = true;
      schedule();
      // every record, drawn or not (a hidden page draws none): its eight events may be gone from the next ones
      eventsPanel.onRecord(r);
      estopSeenInForce(r);
      applyLiveness(state.lastTelemetryAt);   // a page falling behind says so at once, not at the next tick
      break;
    }
    case 'acked': {
      if (!Number.isSafeInteger(msg.n)) return;
      const now = performance.now();
      let answered = null;
      while (state.acksAwaited.length > 0 && state.acksAwaited[0].n <= msg.n) answered = state.acksAwaited.shift();
      if (answered !== null && answered.n === msg.n && Number.isFinite(msg.server_ms)) {
        timeClock(answered, msg.server_ms, now);
      }
      applyLiveness(now);
      break;
    }
    case 'geometry': {
      const g = msg.geometry;
      if (!g || typeof g !== 'object') return;
      state.geometry = g;
      try { view.setGeometry(g); } catch (e) { logMessage('error', '3D view', 'geometry', e && e.message ? e.message : String(e)); }
      const info = [
        `${g.name ?? 'geometry'} · calibration ${g.calibration_id ?? '?'}`,
        g.source ? `source: ${g.source}` : null,
        Array.isArray(g.home) ? `home ${fmtPose(g.home, 1)}` : null,
        Array.isArray(g.stroke) ? `stroke ${fmt(g.stroke[0], 1)} – ${fmt(g.stroke[1], 1)} mm` : null,
      ].filter(Boolean).join('\n');
      setText('geometry-info', info);
      state.newRecord = true;
      schedule();
      break;
    }
    case 'hello': {
      const ms = msg.command_timeout_ms;
      if (typeof ms !== 'number' || !Number.isFinite(ms) || ms <= 0) return;
      state.commandTimeoutMs = ms;
      for (const [id, p] of state.pending) armTimeout(id, p);  // those sent before it: from when they were sent
      break;
    }
    case 'link':
      state.link = { connected: msg.connected === true, message: typeof msg.message === 'string' ? msg.message : '' };
      updateConnection();
      applyLiveness(performance.now());
      controls.onLink(state.link.connected);
      break;
    case 'reply': {
      const p = state.pending.get(msg.id);
      if (!p) return;
      state.pending.delete(msg.id);
      clearTimeout(p.timer);
      p.done(msg.reply);
      break;
    }
    default:
      break;
  }
}

/** Tell the server the page has handled telemetry message `n` (every ACK_EVERY, and every ACK_INTERVAL_MS). */
function acknowledge(n) {
  state.unacknowledged += 1;
  const now = performance.now();
  if (state.unacknowledged < ACK_EVERY && now - state.lastAckAt < ACK_INTERVAL_MS) return;
  if (!Number.isSafeInteger(n) || state.ws?.readyState !== WebSocket.OPEN) return;
  state.unacknowledged = 0;
  state.lastAckAt = now;
  state.ws.send(JSON.stringify({ type: 'ack', n, at: now }));   // `at`: as a command's, on the page's clock
  if (state.acksAwaited.length < ACKS_AWAITED_MAX) state.acksAwaited.push({ n, at: now, wall: Date.now() });
}

/**
 * One sample of the dashboard host's clock against the page's: the server read the
 * acknowledgement `ack` and stamped `serverMs` between its sending and `now` (the page's
 * performance clock), so at about half the round trip. A browser on another host (through
 * an ssh tunnel) has a clock of its own; the latency it shows is on the dashboard's.
 */
function timeClock(ack, serverMs, now) {
  const roundTrip = now - ack.at;
  state.clockSamples.push({ roundTrip, offset: serverMs - (ack.wall + roundTrip / 2) });
  if (state.clockSamples.length > CLOCK_SAMPLES) state.clockSamples.shift();
  state.clockOffset = state.clockSamples.reduce((best, s) => (s.roundTrip < best.roundTrip ? s : best)).offset;
}

/**
 * How far behind the telemetry the page is, ms: since its oldest acknowledgement whose
 * `acked` has not come back. The server sends `acked` behind everything it sent the page
 * before it read the acknowledgement, so until it comes, nothing the page has handled is
 * newer than that acknowledgement. One clock, the page's: a browser on another host's
 * clock measures it as well. 0 with none awaited.
 */
function behindMs(now) {
  return state.acksAwaited.length > 0 ? now - state.acksAwaited[0].at : 0;
}

function connect() {
  const url = `${location.protocol === 'https:' ? 'wss:' : 'ws:'}//${location.host}/ws${location.search}`;   // with its ?token= (CURVE)
  let ws;
  try {
    ws = new WebSocket(url);
  } catch (e) {
    state.wsReason = `cannot open ${url}: ${e && e.message ? e.message : e}; retrying every 1 s`;
    updateConnection();
    setTimeout(connect, RECONNECT_MS);
    return;
  }
  state.ws = ws;
  state.commandTimeoutMs = null;   // this connection's dashboard says it in its hello
  state.unacknowledged = 0;
  state.acksAwaited = [];
  ws.addEventListener('open', () => {
    state.wsOpen = true;
    state.link = null;
    updateConnection();
    applyLiveness(performance.now());
  });
  ws.addEventListener('message', handleMessage);
  ws.addEventListener('close', (ev) => {
    const wasOpen = state.wsOpen;
    state.wsOpen = false;
    state.link = null;
    if (state.ws === ws) state.ws = null;
    state.wsReason = wasOpen
      ? `connection to the dashboard server lost (code ${ev.code}${ev.reason ? `: ${ev.reason}` : ''}); reconnecting every 1 s`
      : 'the dashboard server does not answer; retrying every 1 s';
    updateConnection();
    applyLiveness(performance.now());
    controls.onDisconnect();
    failPending('the connection to the dashboard server closed before the reply');
    setTimeout(connect, RECONNECT_MS);
  });
}

// ---------------- no live data: never show the last state as current ----------------
/**
 * What the page has lost, or null while its telemetry is live:
 * 'server' (the WebSocket to the dashboard server is closed), 'service' (the dashboard server
 * says it has no telemetry from the service), 'telemetry' (none reached the page for STALE_MS),
 * 'starting' (none yet since the page opened; shown as lost after STALE_MS), 'late' (telemetry
 * comes, but the page handles it more slowly than it comes and is over STALE_MS behind),
 * 'loop' (telemetry comes, but the service's control loop has sent nothing for
 * REPORT_SILENT_S: its last state).
 */
function dataLoss(now) {
  const fresh = state.record !== null && now - state.lastTelemetryAt <= STALE_MS;
  if (state.wsOpen && state.link?.connected !== false && fresh) {
    if (behindMs(now) > STALE_MS) return 'late';
    return state.record.loop?.report_age_s > REPORT_SILENT_S ? 'loop' : null;
  }
  if (!state.wsOpen) return state.record === null && now - pageStartedAt <= STALE_MS ? 'starting' : 'server';
  if (state.link && !state.link.connected) return 'service';
  return state.record === null && now - pageStartedAt <= STALE_MS ? 'starting' : 'telemetry';
}

function noDataFor(now, loss) {
  if (loss === 'loop') return `no loop report for ${Math.floor(state.record.loop.report_age_s)} s`;
  if (loss === 'late') return `page ${Math.floor(behindMs(now) / 1000)} s behind`;
  const since = state.record !== null ? state.lastTelemetryAt : pageStartedAt;
  return `no data for ${Math.max(0, Math.floor((now - since) / 1000))} s`;
}

const dataLost = $('data-lost');
const LOSS_TEXT = {
  server: 'The page has lost the dashboard server: nothing on it is current, and no button of it, E-STOP included, can reach the service.',
  service: "The dashboard server has no telemetry from the hexactl service: the service may have stopped, or its telemetry stalled. The page's E-STOP is still sent, but may not be carried out.",
  telemetry: "No telemetry from the hexactl service has reached the page: the service, or the dashboard's link to it, may have stopped. The page's E-STOP is still sent, but may not be carried out.",
  loop: "The hexactl service's control loop has sent nothing for over 1 s: its process is stopped or hung, and what the page shows is its last state. The actuators stop on their own watchdogs; the page's E-STOP is still sent, but cannot be carried out until the loop runs.",
  late: "This page handles the service's telemetry more slowly than it comes (its browser or computer is overloaded, or the tab was held in the background): what it shows is over 2 s old. The page's E-STOP is still sent, but its confirmation comes late.",
};
const LOSS_TODO = {
  server: 'If the platform may be moving, use the HARDWARE E-STOP. The page reconnects by itself every 1 s.',
  service: 'If the platform may be moving, use the HARDWARE E-STOP. The page shows live data again by itself when telemetry returns.',
  telemetry: 'If the platform may be moving, use the HARDWARE E-STOP. The page shows live data again by itself when telemetry returns.',
  loop: 'If the platform may be moving, use the HARDWARE E-STOP. The page shows live data again by itself when the loop reports.',
  late: 'If the platform may be moving, use the HARDWARE E-STOP. Close what loads this computer, or use a page on another; this one shows live data again by itself once it catches up.',
};

/** Live: the readouts as drawn. No live data: state and motion UNKNOWN, the banner, the rest greyed. */
function applyLiveness(now) {
  const loss = dataLoss(now);
  const was = state.loss;
  state.loss = loss;
  const lost = loss !== null && loss !== 'starting';
  if (loss !== was) {
    document.body.classList.toggle('stale', lost);
    document.body.dataset.live = loss === null ? 'true' : 'false';
    document.body.dataset.loss = loss ?? '';
    dataLost.hidden = !lost;
    if (lost) {
      setText('data-lost-what', LOSS_TEXT[loss]);
      setText('data-lost-do', LOSS_TODO[loss]);
      controls.onDataLoss(LOSS_SHORT[loss]);
    }
    updateDismiss();
    if (loss === null) {
      // live again: redraw every readout from the newest record
      for (const id of ['state', 'motion']) $(id).title = '';
      state.newRecord = state.record !== null;
      schedule();
    }
  }
  // an E-stop sent while live whose reply has not come when the data are lost: not confirmed
  if (loss !== null && estopState.awaiting > 0 && !estopState.warning) {
    showEstopWarning(0, notConfirmedYet(loss));
  }
  if (!lost) return;
  const age = noDataFor(now, loss);
  const r = state.record;
  tabTitle('NO LIVE DATA');
  for (const [id, key] of [['state', 'state'], ['motion', 'motion']]) {
    setText(id, 'UNKNOWN');
    const el = $(id);
    if (el.className !== 'pill pill-unknown') el.className = 'pill pill-unknown';
    el.title = `${age}${r && typeof r[key] === 'string' ? `; last received: ${r[key]}` : ''}`;
  }
  setText('data-age', age);
  setText('data-lost-title', `NO LIVE DATA: STATE UNKNOWN (${age})`);
  setText('telemetry-stale', `${age}: the values below are the last received, not the platform now`);
  setText('loop-summary', 'no data');
  setText('latency-summary', 'no data');
  const hud = [`NO LIVE DATA: ${age}`];
  if (r && Array.isArray(r.pose_command)) hud.push(`last command received ${fmtPose(r.pose_command, 2)}`);
  hud.push('state, motion, goal and time to go: unknown');
  setText('view3d-hud', hud.join('\n'));
}

setInterval(() => applyLiveness(performance.now()), TICK_MS);

// the banners sit between the header and the panels: the layout moves down by their height
const alarms = $('alarms');
new ResizeObserver(() => {
  document.documentElement.style.setProperty('--alarms-h', `${alarms.offsetHeight}px`);
}).observe(alarms);

window.hexactlDashboard = {
  legLengths: () => view.legLengths(),
  latencies: () => latencyValues(),
  get connected() { return state.wsOpen && state.link !== null && state.link.connected === true; },
  get record() { return state.record; },
  get geometry() { return state.geometry; },
  /** null while live telemetry is shown, else 'server', 'service', 'telemetry', 'loop', 'late' or 'starting'. */
  get dataLoss() { return state.loss; },
  /** How long the page waits for a command's reply, ms: the dashboard's, from its hello (null before). */
  get commandTimeoutMs() { return state.commandTimeoutMs; },
  /** The E-stop presses' events in order: {press, what ('pressed', 'sent', 'warning', 'reply-ok', 'reply-failed', 'cleared'), detail}. */
  estopEvents: () => estopState.events.map((e) => ({ ...e })),
  get estopWarning() { return estopState.warning; },
  /** The Events panel's lines, newest first: {t, code, message, sender, warning, ago}. */
  events: () => eventsPanel.entries(),
  /** Whether the panel shows an event of this code as a warning. */
  eventIsWarning: (code) => isWarning(code),
  send,
};

updateConnection();
applyLiveness(performance.now());
connect();
