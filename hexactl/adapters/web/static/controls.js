// The control panels: move (validate, then go), jog (press and hold), sequences, leg lock,
// frames and soft limits, calibration, recorder. Each talks to the service through ctx.send.

import { setupCampaign } from './campaign.js';

const $ = (id) => document.getElementById(id);
export const AXES = ['x', 'y', 'z', 'roll', 'pitch', 'yaw'];
const BUILT_IN_SEQUENCES = ['x_sweep', 'y_rotation', 'compound'];
// As hexactl jog (adapters/cli/jog_commands.py): renewals per deadman interval, so that
// three may come late before the platform brakes.
const RENEWALS_PER_DEADMAN = 4;

export const fmt = (v, digits = 3) => (typeof v === 'number' && Number.isFinite(v) ? v.toFixed(digits) : '–');

/** "[x, y, z mm; roll, pitch, yaw °]" for a pose, "none" otherwise. */
export function fmtPose(p, digits = 3) {
  if (!Array.isArray(p) || p.length !== 6) return 'none';
  const n = p.map((v) => (v === null ? 'null' : fmt(v, digits)));
  return `[${n.slice(0, 3).join(', ')} mm; ${n.slice(3).join(', ')} °]`;
}

/** "code: message" of a failed reply or of a refusal, with up to four violations. */
export function describeError(err) {
  if (!err || typeof err !== 'object') return 'refused';
  let text = `${err.code ?? 'error'}: ${err.message ?? ''}`;
  const v = err.details && Array.isArray(err.details.violations) ? err.details.violations : null;
  if (v && v.length) {
    // A single move's violations are all at waypoint 1: named only where a sequence's are.
    const sequence = v.some((x) => x && typeof x === 'object' && Number(x.waypoint) > 1);
    const lines = v.slice(0, 4).map((x) => {
      if (x && typeof x === 'object') {
        const where = x.axis ? x.axis : (x.leg ? `leg ${x.leg}` : '');
        const wp = sequence && x.waypoint !== undefined && x.waypoint !== null ? `waypoint ${x.waypoint}: ` : '';
        return `  • ${wp}${x.message ?? `${x.kind ?? ''} ${where} ${fmt(x.value)} beyond ${fmt(x.limit)}`}`;
      }
      return `  • ${String(x)}`;
    });
    if (v.length > 4) lines.push(`  • … and ${v.length - 4} more`);
    text += `\n${lines.join('\n')}`;
  } else if (err.details && Array.isArray(err.details)) {
    // an invalid_request's {field, problem} items, as the message words them; each once
    const items = err.details.map((d) => (d && typeof d === 'object' && 'problem' in d
      ? (d.field ? `${d.field}: ${d.problem}` : String(d.problem)) : (typeof d === 'string' ? d : JSON.stringify(d))));
    const unsaid = items.filter((item) => !text.includes(item));
    if (unsaid.length) text += `\n${unsaid.slice(0, 4).map((item) => `  • ${item}`).join('\n')}`;
  }
  return text;
}

// A result line saying a move or sequence is under way (its reply's) is live status only
// while the records show it under way: once they have, and show it no more, or the
// controller leaves enabled (a stop or E-stop from anyone), it says it is over.
const underWayLines = new Map();   // result element -> {running(r), over(r), seen}

/** Keep `el`'s line saying it is under way until records show otherwise; then over(r) says how it ended. */
function claimUnderWay(el, running, over) { underWayLines.set(el, { running, over, seen: false }); }

function checkUnderWay(r) {
  for (const [el, c] of underWayLines) {
    if (c.running(r)) c.seen = true;
    else if (c.seen || r.state !== 'enabled') setResult(el, null, c.over(r));
  }
}

// A calibration accepted (previewed, loaded, rolled back to), with what its identification
// warned of (the reply's warnings: weakly determined, the instrument's frame) in amber.
function showCalibration(el, reply, text) {
  const warnings = (Array.isArray(reply.warnings) ? reply.warnings : []).filter((w) => typeof w === 'string');
  setResult(el, warnings.length ? 'cautioned' : 'valid', text + warnings.map((w) => `\nwarning, when identified: ${w}`).join(''));
}

const CONFIRM_MS = 10000;
const CONFIRM_NOT_BEFORE_MS = 400;

/**
 * `button`'s action asks for a second press: the first says in `result` what it would do
 * (`explain(inputs())`: a text, or null when it is refused, which explain says itself) and
 * arms the button for CONFIRM_MS; a second press then, with the same `inputs()` (what the
 * text described: a name, the frames, the calibration in force), does it (`act(inputs())`).
 * Found from outside: Play (a 32 s sequence to x -600 mm, its name filled in), Roll back
 * and Clear all changed the motion, the calibration or every soft limit in one click,
 * beside buttons that validate first. A double-click's second click, a press sooner than
 * CONFIRM_NOT_BEFORE_MS after the question, and a held key's repeats confirm nothing
 * (found from outside: each did).
 */
function confirmed(button, result, inputs, explain, act) {
  const label = button.textContent;
  let armed = null;
  const disarm = () => { armed = null; button.textContent = label; button.classList.remove('armed'); };
  button.addEventListener('keydown', (ev) => { if (ev.repeat) ev.preventDefault(); });
  button.addEventListener('click', async (ev) => {
    if (ev.detail > 1) return;
    const key = inputs(), now = performance.now();
    if (armed && now < armed.from + CONFIRM_NOT_BEFORE_MS) return;
    if (armed && armed.key === key && now < armed.until) {
      disarm();
      setResult(result, null, '');   // the question answered: the reply takes its place
      await act(key);
      return;
    }
    disarm();
    const said = await explain(key);
    if (said === null) return;
    armed = { key, from: performance.now(), until: performance.now() + CONFIRM_MS };
    button.textContent = `Confirm: ${label}`;
    button.classList.add('armed');
    setResult(result, 'cautioned', `${said}. Press "Confirm: ${label}" within ${CONFIRM_MS / 1000} s to go on`);
    setTimeout(() => { if (armed && performance.now() >= armed.until) disarm(); }, CONFIRM_MS + 10);
  });
}

function setResult(el, cls, text) {
  underWayLines.delete(el);
  el.classList.remove('valid', 'refused', 'moving', 'cautioned');
  if (cls) el.classList.add(cls);
  el.textContent = text;
}

// A number as an operator types it: decimal digits with an optional sign, point and
// exponent ("-12.5", ".5", "1e-7"). Not Number()'s rules, under which "" and " " are 0,
// "0x10" is 16, "0b1" is 1 and "Infinity" a number: a typing slip must be refused, never
// taken for another value.
const DECIMAL = /^[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?$/;
const NOT_SENT = 'nothing was sent';

/** The number `text` (trimmed) spells as a plain decimal; NaN for anything else, empty included. */
export function decimal(text) {
  const t = String(text).trim();
  const v = DECIMAL.test(t) ? Number(t) : NaN;
  return Number.isFinite(v) ? v : NaN;
}

/**
 * Six numbers, comma-separated (or separated by spaces), optionally in [ ]; null when the
 * input is empty (left as it is in force). With allowNull an entry `null` or `none` is
 * null (no bound); any other entry that is not a plain decimal number, an empty one or a
 * lone "-" among them, is refused naming the field (`what`) and the entry.
 */
export function parseSix(text, allowNull, what) {
  const s = text.trim();
  if (!s) return null;
  const [opens, closes] = [s.startsWith('['), s.endsWith(']')];
  if (opens !== closes) throw new Error(`${what}: unbalanced bracket: put the six values in [ ] or in none; ${NOT_SENT}`);
  const inner = opens ? s.slice(1, -1).trim() : s;
  const parts = (inner.includes(',') ? inner.split(',') : inner.split(/\s+/)).map((x) => x.trim());
  if (parts.length !== 6) throw new Error(`${what}: six values, x, y, z, roll, pitch, yaw (got ${parts.length}); ${NOT_SENT}`);
  return parts.map((x, i) => {
    const entry = `entry ${i + 1} (${AXES[i]})`;
    if (allowNull && ['null', 'none'].includes(x.toLowerCase())) return null;
    if (x === '') {
      throw new Error(`${what}: ${entry} is empty: type a number${allowNull ? ', or null to remove that bound' : ''}; ${NOT_SENT}`);
    }
    const v = decimal(x);
    if (!Number.isFinite(v)) {
      throw new Error(`${what}: ${entry} "${x}" is not a number${allowNull ? ' (null or none: no bound)' : ''}; ${NOT_SENT}`);
    }
    return v;
  });
}

/** What to say of a number refused for a decimal comma (the fields are text: a number field dropped it, "1,5" became 15). */
function commaHint(text) {
  return String(text).includes(',') ? ' (a decimal point, not a comma: 1.5)' : '';
}

/** A percentage for people: whole below 100 from 10 on, two significant digits below (a slow jog is not "0 %"), as `hexactl jog` says it. */
function percentText(percent) {
  if (percent >= 9.95) return `${percent.toFixed(0)} %`;
  if (percent >= 0.01) return `${Number(percent.toPrecision(2))} %`;
  return 'under 0.01 %';
}

function timestampName() {
  const d = new Date();
  const p = (n) => String(n).padStart(2, '0');
  return `dashboard-${d.getFullYear()}${p(d.getMonth() + 1)}${p(d.getDate())}-${p(d.getHours())}${p(d.getMinutes())}${p(d.getSeconds())}`;
}

/**
 * What a record shows changed since a move was validated under `under` (validate_pose's
 * validated_under: {calibration_id, frames, goal}; the goal is the service's to check),
 * named for people; [] when nothing did.
 */
function changedSince(under, r) {
  const same = (a, b) => JSON.stringify(a) === JSON.stringify(b);
  const frames = r.frames ?? {};
  return [
    ['work frame', same(under.frames.work, frames.work)],
    ['tool frame', same(under.frames.tool, frames.tool)],
    ['soft limits', same(under.frames.soft_limits, frames.soft_limits)],
    ['calibration', under.calibration_id === r.calibration_id],
  ].filter(([, unchanged]) => !unchanged).map(([name]) => name);
}

// The events by which the controller leaves `enabled` or comes back to it: a validated move
// holds only within the enabled spell it was validated in.
const ENABLED_SPELL_ENDS = new Set(['estop', 'disabled', 'reset', 'enabled']);

/** {seq, t}: the newest event a record `r` carries and its time; what came later is newer. */
function eventsSeen(r) {
  const events = Array.isArray(r?.events) ? r.events : [];
  const seqs = events.map((e) => (e && Number.isSafeInteger(e.seq) ? e.seq : 0));
  return { seq: Math.max(0, ...seqs), t: typeof r?.t === 'number' ? r.t : Infinity };
}

/**
 * Why a move validated in the enabled spell that `since` (eventsSeen) was seen in may no
 * longer go by record `r`, or null. The state says it when the page sees it; the events
 * say it too when the page saw no record of it (an E-stop, reset and Enable between two
 * records it handled: it handles the newest at each frame it draws).
 */
function enabledSpellEnded(since, r) {
  if (r.state !== 'enabled') return `the controller is ${r.state}: Go is withdrawn; ${toEnable(r.state)}, then validate again`;
  const events = Array.isArray(r.events) ? r.events : [];
  const codes = events.filter((e) => e && typeof e === 'object' && ENABLED_SPELL_ENDS.has(e.code)
    && ((Number.isSafeInteger(e.seq) && e.seq > since.seq) || (typeof e.t === 'number' && e.t > since.t)))
    .map((e) => e.code);
  if (!codes.length) return null;
  return `the controller left enabled since you validated (${[...new Set(codes)].join(', ')}): Go is withdrawn; validate again`;
}

/** What the operator does to get `state` back to enabled: a latched fault or E-stop is reset first. */
const toEnable = (state) => (['fault', 'estop'].includes(state) ? 'reset, then enable it' : 'enable it');

const WAVE_RUNNING = new Set(['ramp_in', 'steady', 'ramp_out']);

/**
 * Why the platform is not at rest by record `r` (moving, or a sequence, wave or pose stream
 * under way), or null: a move validated or a calibration previewed now would not start from
 * where it will be, so Go and Apply are armed only at rest.
 */
function notAtRest(r) {
  if (!r) return null;
  if (r.motion !== 'holding') return `the platform is ${r.motion}`;
  if (r.sequence) return 'a sequence is under way';
  if (r.stream) return 'a pose stream is under way';
  if (r.wave && WAVE_RUNNING.has(r.wave.phase)) return 'a wave is under way';
  return null;
}

/**
 * ctx: { send(cmd, fields) -> Promise<reply>, setGhost(goal|null), record() -> last record,
 *        noLiveData() -> null while the page has live data, else what is lost (a phrase) }
 * Returns hooks the app calls: onRecord(record), onLink(connected), onDisconnect(), onDataLoss(why),
 * releaseJog(sendZero).
 */
export function setupControls(ctx) {
  // ---------------- controller ----------------
  const simple = (id, cmd, resultEl) => $(id).addEventListener('click', async () => {
    const reply = await ctx.send(cmd);
    if (resultEl) setResult(resultEl, reply.ok ? 'valid' : 'refused', reply.ok ? reply.message ?? 'ok' : describeError(reply.error));
    return reply;
  });
  simple('enable', 'enable');
  simple('disable', 'disable');
  simple('reset', 'reset');
  $('stop').addEventListener('click', () => { releaseJog(false); ctx.send('stop'); });

  // ---------------- move ----------------
  const moveIds = [...AXES.map((a) => `move-${a}`), 'move-frame', 'move-relative', 'move-duration', 'move-speed'];
  const moveResult = $('move-result');
  const goButton = $('move-go');
  let validated = null;   // {key, fields, goal, ref, under, since}
  let withdrawnIn = null; // the state whose advice ("the controller is estop: … reset, then enable") the Move line shows
  let validating = 0;

  function readMove() {
    const pose = AXES.map((a) => {
      const t = $(`move-${a}`).value.trim();
      if (t === '') throw new Error(`${a}: empty: type a number (0 for none); ${NOT_SENT}`);
      const v = decimal(t);
      if (!Number.isFinite(v)) throw new Error(`${a}: "${t}" is not a number${commaHint(t)}; ${NOT_SENT}`);
      return v;
    });
    const fields = { pose, frame: $('move-frame').value, relative: $('move-relative').checked };
    for (const [id, key] of [['move-duration', 'duration'], ['move-speed', 'speed']]) {
      const t = $(id).value.trim();
      if (t !== '') {   // empty: none
        const v = decimal(t);
        if (!Number.isFinite(v)) throw new Error(`${key}: "${t}" is not a number${commaHint(t)} (empty: none); ${NOT_SENT}`);
        fields[key] = v;
      }
    }
    if (fields.duration !== undefined && fields.speed !== undefined) throw new Error('give a duration or a speed, not both');
    return fields;
  }

  const motionRef = (r) => (r ? (Array.isArray(r.goal) ? r.goal : r.pose_command) : null);

  function invalidate(text) {
    const had = validated !== null;
    validated = null;
    goButton.disabled = true;
    goButton.title = 'Validate the inputs first';
    ctx.setGhost(null);
    if (text && had) setResult(moveResult, null, text);
  }

  moveIds.forEach((id) => {
    $(id).addEventListener('input', () => invalidate('inputs changed: validate again'));
    $(id).addEventListener('change', () => invalidate('inputs changed: validate again'));
  });

  // This page's E-stop (the button or Escape: app.js's estop() calls it), Disable and Reset
  // end the enabled spell: Go is withdrawn at the press, before any record says so, and a
  // validation under way is dropped (it began before the press).
  function withdrawnBy(press) {
    const underWay = moveResult.textContent === 'validating…';
    validating += 1;
    if (validated || underWay) {
      invalidate();
      setResult(moveResult, null, `${press} pressed: Go is withdrawn; ${toEnable(press.startsWith('E-STOP') ? 'estop' : 'disabled')}, then validate again`);
    }
  }
  $('disable').addEventListener('click', () => withdrawnBy('Disable'));
  $('reset').addEventListener('click', () => withdrawnBy('Reset'));

  $('move-validate').addEventListener('click', async () => {
    let fields;
    try { fields = readMove(); } catch (e) { invalidate(); setResult(moveResult, 'refused', e.message); return; }
    invalidate();
    const key = JSON.stringify(fields);
    const token = ++validating;
    setResult(moveResult, null, 'validating…');
    const before = ctx.record();
    const since = eventsSeen(before);   // the enabled spell it is validated in: see enabledSpellEnded
    const ref = motionRef(before);
    const reply = await ctx.send('validate_pose', fields);
    if (token !== validating) return;                       // a newer validation is under way
    let current;
    try { current = JSON.stringify(readMove()); } catch (e) { current = null; }
    if (current !== key) { setResult(moveResult, null, 'inputs changed while validating: validate again'); return; }
    if (!reply.ok) { setResult(moveResult, 'refused', describeError(reply.error)); return; }
    if (!reply.valid) { setResult(moveResult, 'refused', describeError(reply.refusal ?? { code: 'refused', message: reply.message })); return; }
    const blind = ctx.noLiveData();
    if (blind) { setResult(moveResult, 'refused', `valid, but the page has no live data (${blind}): validate again once live data return`); return; }
    // what it was validated under goes with the move: the service refuses it if that changed meanwhile
    const under = reply.validated_under && typeof reply.validated_under.frames === 'object' ? reply.validated_under : null;
    const lines = [`valid: duration ${fmt(reply.duration, 2)} s`, `goal ${fmtPose(reply.goal)}`];
    // Go is armed only in the enabled spell the validation was made in (E-stop, fault,
    // disable, reset end it: enabledSpellEnded)
    const now = ctx.record();
    const ended = before && before.state === 'enabled' && now ? enabledSpellEnded(since, now) : null;
    const moving = ended ? null : (notAtRest(before) ?? notAtRest(now));
    const armed = before && before.state === 'enabled' && now && !ended && !moving;
    if (armed) {
      validated = { key, fields, goal: reply.goal ?? null, ref: Array.isArray(ref) ? ref.slice() : null, under, since };
      goButton.disabled = false;
      goButton.title = 'Move to the validated goal';
      ctx.setGhost(Array.isArray(reply.goal) ? reply.goal : null);
    }
    if (Array.isArray(reply.tool_goal)) lines.push(`tool goal (work frame) ${fmtPose(reply.tool_goal)}`);
    const acc = reply.predicted_accuracy;
    if (acc && typeof acc === 'object') {
      lines.push(`predicted accuracy (1σ at the tool point): ${fmt(acc.position_mm, 3)} mm, ${fmt(acc.orientation_deg, 4)} °`);
    } else if (typeof acc === 'number') {
      lines.push(`predicted accuracy (1σ): ${fmt(acc, 3)} mm`);
    } else {
      lines.push('predicted accuracy: not available (no calibration covariance)');
    }
    if (!armed) {
      const state = now?.state ?? before?.state ?? 'unknown';
      if (ended) lines.push(ended.replace('Go is withdrawn', 'Go is not armed'));
      else if (moving && state === 'enabled') lines.push(`Go is not armed: ${moving}; validate again once it is at rest`);
      else lines.push(`Go is not armed: the controller is ${state}; ${toEnable(state)}, then validate again`);
    }
    setResult(moveResult, armed ? 'valid' : null, lines.join('\n'));
  });

  goButton.addEventListener('click', async () => {
    let key;
    try { key = JSON.stringify(readMove()); } catch (e) { key = null; }
    if (!validated || key !== validated.key) { invalidate(); setResult(moveResult, 'refused', 'validate the inputs first'); return; }
    const { under } = validated;
    const fields = under ? { ...validated.fields, validated_under: under } : validated.fields;
    invalidate();
    const blind = ctx.noLiveData();   // lost since the last liveness tick, which calls onDataLoss
    if (blind) { setResult(moveResult, 'refused', `not sent: the page has no live data (${blind}); validate again once live data return`); return; }
    setResult(moveResult, null, 'sending move…');
    const reply = await ctx.send('move', fields);
    if (reply.ok) {
      setResult(moveResult, 'moving', `${reply.message ?? 'moving'}: goal ${fmtPose(reply.goal)}, duration ${fmt(reply.duration, 2)} s`);
      const goal = reply.goal;
      claimUnderWay(moveResult, (r) => r.motion !== 'holding', (r) => {
        if (r.state !== 'enabled') return `move over: the controller is ${r.state}`;
        const reached = Array.isArray(goal) && Array.isArray(r.pose_command)
          && goal.every((v, i) => Math.abs(v - r.pose_command[i]) <= 0.01);
        return `move over: ${reached ? 'at its goal' : 'stopped before its goal'}, at rest at ${fmtPose(r.pose_command)}`;
      });
    } else {
      setResult(moveResult, 'refused', describeError(reply.error));
    }
  });

  $('move-from-current').addEventListener('click', () => {
    const r = ctx.record();
    if (!r || !Array.isArray(r.pose_command)) return;
    AXES.forEach((a, i) => { $(`move-${a}`).value = (Math.round(r.pose_command[i] * 1000) / 1000).toString(); });
    $('move-frame').value = 'zero';
    $('move-relative').checked = false;
    invalidate('inputs changed: validate again');
  });

  // ---------------- jog ----------------
  const jogStatus = $('jog-status');
  let jog = null;          // {button, velocity, frame, timer, everyMs, number, lapsed}: number, the jog the renewals name; lapsed, the one a restart names
  let jogSerial = 0;
  let jogInFlight = 0;
  let renewEveryMs = 50;   // the default deadman's (0.2 s) quarter, until a jog's reply says the service's

  /** The jog speed typed (mm/s, °/s); an Error saying why when it is not a number > 0. */
  function jogSpeed() {
    const t = $('jog-speed').value.trim();
    if (t === '') throw new Error('jog speed: empty: type a speed in mm/s, °/s; not sent');
    const speed = decimal(t);
    if (!Number.isFinite(speed) || speed < 0) throw new Error(`jog speed: "${t}" is not a number > 0${commaHint(t)}; not sent`);
    // 0 would be a jog's release to the service: "nothing to release", said of a press
    if (speed === 0) throw new Error('jog speed: 0 moves nothing: type a speed > 0 in mm/s, °/s; not sent');
    return speed;
  }

  function jogVelocity(button, speed) {
    const axis = AXES.indexOf(button.dataset.axis);
    const dir = Number(button.dataset.direction) < 0 ? -1 : 1;
    const v = [0, 0, 0, 0, 0, 0];
    if (axis >= 0) v[axis] = dir * speed;
    return v;
  }

  // As hexactl jog: a renewal names its jog, so that a stop from anyone ends the held jog for
  // good (the service refuses the renewal, jog_ended) instead of the next renewal starting
  // a new one; only a lapse of the deadman (this page stalled) starts it again.
  async function sendJog(velocity, frame, held = null) {
    const serial = ++jogSerial;
    jogInFlight += 1;
    const fields = { velocity, frame };
    if (held && held.number != null) fields.renews = held.number;
    else if (held && held.lapsed != null) fields.restarts = held.lapsed;   // refused if a stop came after the lapse
    // until the jog that starts it is answered, no renewal: each would start a jog of its own
    const starting = held !== null && fields.renews === undefined;
    if (starting) held.starting = true;
    let reply;
    try { reply = await ctx.send('jog', fields); } finally { jogInFlight -= 1; if (starting) held.starting = false; }
    if (reply.ok && typeof reply.deadman_s === 'number' && reply.deadman_s > 0) renewEvery(reply.deadman_s * 1000 / RENEWALS_PER_DEADMAN);
    if (held && held === jog) {
      if (reply.ok && reply.jog != null) { held.number = reply.jog; held.lapsed = null; }
      if (!reply.ok && starting) {
        // the jog pressed is refused: the button is released here, so that no renewal, the
        // release's reply or the state's "jog released" stands in for why (a renewal's refusal,
        // expired say, is followed by the next as usual)
        releaseJog(false);
        setResult(jogStatus, 'refused', describeError(reply.error));
        return;
      }
      if (!reply.ok && reply.error && reply.error.code === 'jog_ended') {
        // several renewals of the lapsed jog may be answered so: the restart names that jog, whichever reply came first
        const details = reply.error.details || {};
        if (details.lapsed) { held.lapsed = details.jog ?? held.number ?? held.lapsed; held.number = null; }
        else {
          releaseJog(false);
          setResult(jogStatus, 'refused', describeError(reply.error));
          return;
        }
      }
    }
    if (serial !== jogSerial) return;   // only the newest request's reply is shown
    if (reply.ok) {
      const extra = [];
      if (reply.end) extra.push(`to ${reply.end}`);
      if (typeof reply.speed === 'number') extra.push(`${percentText(reply.speed * 100)} of the motion limits`);
      setResult(jogStatus, jog ? 'moving' : null, `${reply.message ?? 'ok'}${extra.length ? ` (${extra.join(', ')})` : ''}`);
    } else {
      setResult(jogStatus, 'refused', describeError(reply.error));
    }
  }

  function startJog(button) {
    releaseJog(false);
    const blind = ctx.noLiveData();
    if (blind) { setResult(jogStatus, 'refused', `not sent: the page has no live data (${blind})`); return; }
    let speed;
    try { speed = jogSpeed(); } catch (e) { setResult(jogStatus, 'refused', e.message); return; }
    const velocity = jogVelocity(button, speed);
    const frame = $('jog-frame').value;
    jog = { button, velocity, frame, timer: null, everyMs: null, number: null, lapsed: null, starting: false };
    button.classList.add('held');
    sendJog(velocity, frame, jog);
    renewEvery(renewEveryMs);
  }

  /** Renew the held jog every `ms` (from the service's deadman) from now on. */
  function renewEvery(ms) {
    renewEveryMs = ms;
    if (!jog || jog.everyMs === ms) return;
    clearInterval(jog.timer);
    jog.everyMs = ms;
    jog.timer = setInterval(() => {
      // never pile up renewals behind a slow link: a lapsed deadman brakes, which is safe
      if (jog && !jog.starting && jogInFlight < RENEWALS_PER_DEADMAN - 1) sendJog(jog.velocity, jog.frame, jog);
    }, ms);
  }

  /** Stop renewing the jog; with sendZero, release it at once with a zero velocity, else let the deadman brake it. */
  function releaseJog(sendZero = true) {
    if (!jog) return;
    const { button, frame, timer } = jog;
    clearInterval(timer);
    button.classList.remove('held');
    jog = null;
    if (sendZero) sendJog([0, 0, 0, 0, 0, 0], frame);
    else jogSerial += 1;   // a renewal's late reply must not say "jogging" over why it stopped
  }

  document.querySelectorAll('button.jog').forEach((button) => {
    button.addEventListener('pointerdown', (ev) => {
      if (ev.pointerType === 'mouse' && ev.button !== 0) return;
      ev.preventDefault();
      startJog(button);
    });
    for (const type of ['pointerup', 'pointerleave', 'pointercancel', 'lostpointercapture']) {
      button.addEventListener(type, () => { if (jog && jog.button === button) releaseJog(true); });
    }
    button.addEventListener('contextmenu', (ev) => ev.preventDefault());
    // No jog from the keyboard: a key's release can be lost (focus moved, auto-repeat), and
    // the held pointer is the deadman. Said, so that the key does not seem to do nothing.
    button.addEventListener('keydown', (ev) => {
      if (ev.key !== ' ' && ev.key !== 'Enter') return;
      ev.preventDefault();
      setResult(jogStatus, 'refused', 'not sent: jog by pressing and holding a ± button with the mouse or a finger; the keyboard does not jog');
    });
  });
  window.addEventListener('pointerup', () => { if (jog) releaseJog(true); });
  window.addEventListener('blur', () => { if (jog) releaseJog(true); });
  document.addEventListener('visibilitychange', () => { if (document.hidden && jog) releaseJog(true); });
  $('jog-frame').addEventListener('change', () => { if (jog) releaseJog(true); });

  // ---------------- sequence ----------------
  const seqResult = $('sequence-result');
  const sequenceOver = (r) => (r.state !== 'enabled' ? `sequence over: the controller is ${r.state}`
    : `sequence over: ${r.last_sequence?.status ?? 'ended'}${r.last_sequence?.name ? ` (${r.last_sequence.name})` : ''}`);
  /** The reply in the Sequence panel; an ok one but Abort's says the sequence is under way, until it is not. */
  function seqReply(reply, okText, underWayNow = true) {
    setResult(seqResult, reply.ok ? 'valid' : 'refused', reply.ok ? okText(reply) : describeError(reply.error));
    if (reply.ok && underWayNow) claimUnderWay(seqResult, (r) => Boolean(r.sequence), sequenceOver);
  }
  // what Play's question describes: the sequence, and the frames and calibration it is planned in
  const inForce = () => JSON.stringify([ctx.record()?.frames ?? null, ctx.record()?.calibration_id ?? null]);
  confirmed($('play'), seqResult, () => JSON.stringify([$('sequence-name').value.trim(), inForce()]), async (key) => {
    const [name] = JSON.parse(key);
    if (!name) { setResult(seqResult, 'refused', 'name a sequence: a built-in or a file'); return null; }
    const blind = ctx.noLiveData();
    if (blind) { setResult(seqResult, 'refused', `not sent: the page has no live data (${blind}), so it cannot show what the sequence would start from`); return null; }
    const reply = await ctx.send('validate_sequence', { sequence: name });
    if (!reply.ok) { setResult(seqResult, 'refused', describeError(reply.error)); return null; }
    if (!reply.valid) { setResult(seqResult, 'refused', describeError(reply.refusal)); return null; }
    return `${reply.name ?? name}: ${reply.waypoints} waypoints, ${fmt(reply.duration, 1)} s, ending at ${fmtPose(reply.goal)} (relative to the zero posture)${lockShift(reply.lock_corrections_mm)}`;
  }, async (key) => {
    const reply = await ctx.send('play', { sequence: JSON.parse(key)[0] });
    seqReply(reply, (r) => `${r.message ?? 'playing'}${r.name ? `: ${r.name}` : ''}${r.waypoints !== undefined ? `, ${Array.isArray(r.waypoints) ? r.waypoints.length : r.waypoints} waypoints` : ''}${typeof r.duration === 'number' ? `, ${r.duration.toFixed(1)} s` : ''}${lockShift(r.lock_corrections_mm)}`);
  });
  /** With a leg locked each waypoint goes to the nearest pose that keeps its length: say how far, at most. */
  const lockShift = (corrections) => (Array.isArray(corrections) && corrections.length
    ? `; projected onto the locked leg: waypoints move by up to ${Math.max(...corrections).toFixed(3)} mm` : '');
  for (const cmd of ['pause', 'resume', 'abort']) {
    $(cmd).addEventListener('click', async () => {
      if (cmd === 'abort') releaseJog(false);
      const reply = await ctx.send(cmd);
      seqReply(reply, (r) => r.message ?? cmd, cmd !== 'abort');
    });
  }

  // ---------------- leg lock ----------------
  const lockResult = $('leglock-result');
  $('leglock').addEventListener('click', async () => {
    const reply = await ctx.send('leg_lock', { leg: Number($('leglock-leg').value) });
    setResult(lockResult, reply.ok ? 'valid' : 'refused', reply.ok ? reply.message ?? 'locked' : describeError(reply.error));
  });
  $('unlock').addEventListener('click', async () => {
    const reply = await ctx.send('leg_unlock');
    setResult(lockResult, reply.ok ? 'valid' : 'refused', reply.ok ? reply.message ?? 'unlocked' : describeError(reply.error));
  });

  // ---------------- frames & soft limits ----------------
  const framesResult = $('frames-result');
  let framesApplied = null;   // framesKey of the frames this page set last, while its result is shown
  let framesInForce = false;  // a record has shown them in force since (an older record, still on its way, does not)
  const framesKey = (f) => JSON.stringify(f ? [f.work, f.tool, f.soft_limits?.lower, f.soft_limits?.upper,
    f.soft_limits?.max_tilt_deg] : null);
  const NO_FRAMES = 'work: none · tool: none · soft limits: none';
  function describeFrames(f) {
    if (!f || typeof f !== 'object') return NO_FRAMES;
    const sl = f.soft_limits;
    let soft = 'none';
    if (sl && typeof sl === 'object') {
      const parts = [];
      if (Array.isArray(sl.lower) && sl.lower.some((v) => v !== null)) parts.push(`lower ${fmtPose(sl.lower, 2)}`);
      if (Array.isArray(sl.upper) && sl.upper.some((v) => v !== null)) parts.push(`upper ${fmtPose(sl.upper, 2)}`);
      if (typeof sl.max_tilt_deg === 'number') parts.push(`tilt ≤ ${fmt(sl.max_tilt_deg, 2)} °`);
      soft = parts.length ? parts.join('\n  ') : 'none';
    }
    // a zero frame is no frame, as hexactl status says it (telemetry_text.NO_FRAMES)
    const frame = (p) => (Array.isArray(p) && p.every((v) => v === 0) ? 'none' : fmtPose(p, 2));
    const [work, tool] = [frame(f.work), frame(f.tool)];
    if (work === 'none' && tool === 'none' && soft === 'none') return NO_FRAMES;
    return `work: ${work}\ntool: ${tool}\nsoft limits: ${soft}`;
  }
  $('frames-apply').addEventListener('click', async () => {
    const fields = {};
    try {
      const work = parseSix($('frame-work').value, false, 'work frame');
      const tool = parseSix($('frame-tool').value, false, 'tool frame');
      const lower = parseSix($('soft-lower').value, true, 'soft lower bounds');
      const upper = parseSix($('soft-upper').value, true, 'soft upper bounds');
      const tiltText = $('soft-max-tilt').value.trim();
      // undefined: unchanged; null: no bound
      const tilt = tiltText === '' ? undefined
        : (['none', 'null'].includes(tiltText.toLowerCase()) ? null : decimal(tiltText));
      if (typeof tilt === 'number' && !Number.isFinite(tilt)) {
        throw new Error(`max tilt: "${tiltText}" is not a number (none: no bound; empty: unchanged); ${NOT_SENT}`);
      }
      if (work) fields.work = work;
      if (tool) fields.tool = tool;
      // Only what is filled in changes; the service keeps every other soft limit in force
      // (soft_limit_changes), whatever this page last heard.
      const changes = {};
      const byAxis = (six) => Object.fromEntries(AXES.map((axis, i) => [axis, six[i]]));
      if (lower) changes.lower = byAxis(lower);
      if (upper) changes.upper = byAxis(upper);
      if (tilt !== undefined) changes.max_tilt_deg = tilt;
      if (Object.keys(changes).length) fields.soft_limit_changes = changes;
    } catch (e) {
      setResult(framesResult, 'refused', e.message);
      return;
    }
    if (!Object.keys(fields).length) { setResult(framesResult, 'refused', 'nothing to apply: fill a frame or a soft limit'); return; }
    const reply = await ctx.send('set_frames', fields);
    setResult(framesResult, reply.ok ? 'valid' : 'refused', reply.ok ? `${reply.message ?? 'frames set'}\n${describeFrames(reply.frames)}` : describeError(reply.error));
    framesApplied = reply.ok ? framesKey(reply.frames) : null;
    framesInForce = false;
  });
  confirmed($('frames-clear'), framesResult, () => JSON.stringify(ctx.record()?.frames ?? null), async () => {
    const f = ctx.record()?.frames;
    return `clears the work frame, the tool frame and every soft limit (now: ${describeFrames(f).replace(/\n/g, '; ')})`;
  }, async () => {
    const reply = await ctx.send('clear_frames');
    setResult(framesResult, reply.ok ? 'valid' : 'refused', reply.ok ? reply.message ?? 'frames cleared' : describeError(reply.error));
    framesApplied = reply.ok ? framesKey(reply.frames) : null;
    framesInForce = false;
  });
  $('frames-fill').addEventListener('click', () => {
    const f = ctx.record()?.frames;
    const six = (p) => (Array.isArray(p) ? p.map((v) => (v === null ? 'null' : String(v))).join(', ') : '');
    $('frame-work').value = six(f?.work);
    $('frame-tool').value = six(f?.tool);
    $('soft-lower').value = six(f?.soft_limits?.lower);
    $('soft-upper').value = six(f?.soft_limits?.upper);
    $('soft-max-tilt').value = typeof f?.soft_limits?.max_tilt_deg === 'number' ? String(f.soft_limits.max_tilt_deg) : '';
  });

  // ---------------- files: calibrations and sequences ----------------
  const calSelect = $('calibration-files');
  const calChange = $('calibration-change');
  const calResult = $('calibration-result');
  const calApply = $('calibration-apply');
  let previewed = null;   // {path, id, state, active, ref}: the file previewed valid, the calibration id the
                          // preview answered, and the state, calibration in force and pose it was made in
  let previewing = 0;

  async function refreshFiles() {
    const reply = await ctx.send('files');
    if (!reply.ok || !Array.isArray(reply.files)) return;
    const files = reply.files.filter((f) => f && typeof f.name === 'string');
    const cals = files.filter((f) => f.kind === 'calibration');
    const keep = calSelect.value;
    calSelect.textContent = '';
    if (!cals.length) {
      calSelect.append(new Option('(no calibration files)', ''));
    } else {
      for (const f of cals) {
        const when = typeof f.modified === 'string' ? f.modified.replace('T', ' ').slice(0, 16) : '';
        const opt = new Option(`${f.name}${when ? `  (${when})` : ''}`, f.name);
        if (f.directory) opt.title = `${f.directory}/${f.name}`;
        calSelect.append(opt);
      }
      if (cals.some((f) => f.name === keep)) calSelect.value = keep;
    }
    if (calSelect.value !== keep) resetPreview();
    const list = $('sequence-list');
    list.textContent = '';
    const names = [...BUILT_IN_SEQUENCES, ...files.filter((f) => f.kind === 'sequence').map((f) => f.name)];
    for (const n of [...new Set(names)]) list.append(new Option(n, n));
  }
  $('calibration-refresh').addEventListener('click', refreshFiles);
  $('sequence-refresh').addEventListener('click', refreshFiles);

  function resetPreview(text = '') {
    previewed = null;
    calApply.disabled = true;
    setResult(calChange, null, text);
  }
  calSelect.addEventListener('change', () => { previewing += 1; resetPreview(); });

  /** Why a preview made as `p` says no longer what Apply would do by record `r`, or null. */
  function previewOutdated(p, r) {
    if (r.state !== p.state) return `the controller is ${r.state} now (${p.state} when previewed): preview again`;
    const moving = notAtRest(r);
    if (moving) return `${moving}: Apply is disabled; preview again once it is at rest`;
    if (r.calibration_id !== p.active) return `the calibration in force changed (now ${r.calibration_id}): preview again`;
    const ref = motionRef(r);
    if (Array.isArray(p.ref) && Array.isArray(ref) && ref.some((v, i) => typeof v === 'number' && Math.abs(v - p.ref[i]) > 0.01)) {
      return 'the platform moved since the preview: preview again';
    }
    return null;
  }

  $('calibration-preview').addEventListener('click', async () => {
    const path = calSelect.value;
    resetPreview();
    if (!path) { setResult(calChange, 'refused', 'no calibration file selected: refresh the list'); return; }
    setResult(calChange, null, 'previewing…');
    const token = ++previewing;
    const before = ctx.record();
    const reply = await ctx.send('validate_calibration', { path });
    if (token !== previewing) return;                       // a newer preview, or another file chosen
    if (calSelect.value !== path) { resetPreview(); return; }
    if (!reply.ok) { setResult(calChange, 'refused', describeError(reply.error)); return; }
    if (reply.valid === false) { setResult(calChange, 'refused', describeError(reply.refusal ?? { code: 'refused', message: reply.message })); return; }
    if (typeof reply.calibration_id !== 'string' || !reply.calibration_id) {
      setResult(calChange, 'refused', 'the preview named no calibration: preview again');
      return;
    }
    const blind = ctx.noLiveData();
    if (blind || !before) { setResult(calChange, 'refused', `the page has no live data (${blind ?? 'no record yet'}): preview again once live data return`); return; }
    const ref = motionRef(before);
    const made = { path, id: reply.calibration_id, state: before.state, active: before.calibration_id, ref: Array.isArray(ref) ? ref.slice() : null };
    // made while moving, or changed while the preview was under way
    const outdated = previewOutdated(made, before) ?? previewOutdated(made, ctx.record());
    if (outdated) { resetPreview(outdated); return; }
    previewed = made;
    calApply.disabled = false;
    // the service's message says why the change may be 0 (not enabled: nothing ramped) and what the new calibration shifts
    showCalibration(calChange, reply, `change ${fmt(reply.change_mm, 3)} mm, calibration ${reply.calibration_id}${reply.message ? `\n${reply.message}` : ''}`);
  });
  calApply.addEventListener('click', async () => {
    const path = calSelect.value;
    if (!previewed || previewed.path !== path) { resetPreview(); return; }
    // the calibration previewed goes with it: the service refuses the file if it now holds another
    const expected = previewed.id;
    resetPreview('used by Apply (below): preview again for another change');
    const reply = await ctx.send('load_calibration', { path, expected_id: expected });
    if (!reply.ok) { setResult(calResult, 'refused', describeError(reply.error)); return; }
    showCalibration(calResult, reply, `${reply.message ?? 'loaded'}: calibration ${reply.calibration_id ?? '?'}, change ${fmt(reply.change_mm, 3)} mm`);
  });
  confirmed($('calibration-rollback'), calResult, () => ctx.record()?.calibration_id ?? '', async () =>
    `returns to the calibration active before the last load (now ${ctx.record()?.calibration_id ?? '?'}): the set-points change by its difference, ramped while enabled`,
  async () => {
    const reply = await ctx.send('rollback_calibration');
    if (!reply.ok) { setResult(calResult, 'refused', describeError(reply.error)); return; }
    showCalibration(calResult, reply, `${reply.message ?? 'rolled back'}: calibration ${reply.calibration_id ?? '?'}, change ${fmt(reply.change_mm, 3)} mm`);
  });

  // ---------------- recorder ----------------
  const recName = $('record-name');
  const recResult = $('record-result');
  recName.value = timestampName();
  $('record-start').addEventListener('click', async () => {
    const name = recName.value.trim();
    const duration = decimal($('record-duration').value);
    if (!name) { setResult(recResult, 'refused', 'name the recording'); return; }
    if (!Number.isFinite(duration) || duration <= 0) {
      setResult(recResult, 'refused', `duration: a positive number of seconds${commaHint($('record-duration').value)}`);
      return;
    }
    const reply = await ctx.send('record', { name, duration_s: duration });
    if (reply.ok) {
      setResult(recResult, 'valid', `${reply.message ?? 'recording'}${reply.rows ? `: ${reply.rows} rows` : ''}${reply.rate_hz ? ` at ${reply.rate_hz} Hz` : ''}`);
      recName.value = timestampName();   // ready for the next one (an existing name is refused)
    } else {
      setResult(recResult, 'refused', describeError(reply.error));
    }
  });
  $('record-stop').addEventListener('click', async () => {
    const reply = await ctx.send('record_stop');
    setResult(recResult, reply.ok ? 'valid' : 'refused', reply.ok ? reply.message ?? 'stopped' : describeError(reply.error));
  });

  // ---------------- per-record updates ----------------
  const shown = {};
  const setText = (id, text) => { if (shown[id] !== text) { shown[id] = text; $(id).textContent = text; } };

  const updateCampaign = setupCampaign();

  function onRecord(r) {
    updateCampaign(r.campaign);
    // the page's own frames result holds while they are in force (another client may change them)
    if (framesApplied !== null && r.frames) {
      if (framesKey(r.frames) === framesApplied) framesInForce = true;
      else if (framesInForce) {
        framesApplied = null;
        setResult(framesResult, null, 'the frames in force have changed since this page set them (another client?): '
          + 'see what is in force above');
      }
    }
    // sequence progress
    const s = r.sequence;
    if (s && typeof s === 'object') {
      setText('sequence-text', `${s.name ?? '?'} ${s.index ?? '?'}/${s.total ?? '?'} ${s.phase ?? ''}`.trim());
      const total = Number(s.total) || 0;
      const done = Math.max(0, (Number(s.index) || 0) - (s.phase === 'dwelling' ? 0 : 1));
      $('sequence-bar').value = total ? Math.min(1, done / total) : 0;
    } else {
      setText('sequence-text', 'none');
      $('sequence-bar').value = 0;
    }
    // leg lock
    setText('locked-leg', Number.isInteger(r.locked_leg) ? `leg ${r.locked_leg}` : 'none');
    // frames
    setText('frames-current', describeFrames(r.frames));
    // recording
    const rec = r.recording;
    const link = $('record-download');
    if (rec && typeof rec === 'object') {
      const rows = `${rec.rows ?? 0}${rec.rows_requested ? `/${rec.rows_requested}` : ''} rows`;
      const lost = rec.lost ? `, ${rec.lost} lost` : '';
      const ended = rec.ended ? `, ended: ${rec.ended}` : '';
      setText('record-status', `${rec.state ?? '?'}: ${rec.name ?? ''}, ${rows}${lost}${ended}`);
      if (rec.state === 'done' && typeof rec.name === 'string' && rec.name) {
        const href = `/recordings/${encodeURIComponent(rec.name)}.csv`;
        if (link.getAttribute('href') !== href) {
          link.setAttribute('href', href);
          link.setAttribute('download', `${rec.name}.csv`);
          link.textContent = `Download ${rec.name}.csv`;
        }
        link.hidden = false;
      } else {
        link.hidden = true;
      }
    } else {
      setText('record-status', 'idle');
      link.hidden = true;
    }
    // a validation holds only while the platform stays where it was validated from
    if (validated && Array.isArray(validated.ref)) {
      const ref = motionRef(r);
      if (Array.isArray(ref) && ref.some((v, i) => typeof v === 'number' && Math.abs(v - validated.ref[i]) > 0.01)) {
        invalidate('the platform moved since the validation: validate again');
      }
    }
    // … and in the frames and on the calibration it was validated under (another client may change them)
    if (validated && validated.under) {
      const changed = changedSince(validated.under, r);
      if (changed.length) invalidate(`the ${changed.join(' and the ')} changed since you validated: validate again`);
    }
    // … and only in the enabled spell it was validated in
    if (withdrawnIn && r.state !== withdrawnIn) {   // its advice followed (or overtaken): say what happened, not what to do
      const shown = moveResult.textContent.startsWith(`the controller is ${withdrawnIn}:`);
      if (shown) setResult(moveResult, null, `Go was withdrawn when the controller went ${withdrawnIn}: validate again`);
      withdrawnIn = null;
    }
    if (validated) {
      const ended = enabledSpellEnded(validated.since, r);
      if (ended) invalidate(ended);
      if (ended && r.state !== 'enabled') withdrawnIn = r.state;
    }
    // … and only at rest: a move under way carries it elsewhere than where it was validated from
    const moving = validated ? notAtRest(r) : null;
    if (moving) invalidate(`${moving}: Go is withdrawn; validate again once it is at rest`);
    checkUnderWay(r);
    // a calibration preview holds only in the state, on the calibration and at the pose it was made in
    if (previewed) {
      const why = previewOutdated(previewed, r);
      if (why) resetPreview(why);
    }
    if (!['enabled'].includes(r.state) && jog) {
      // a jog cannot run disabled/latched: stop renewing (the service refuses it anyway)
      releaseJog(false);
      setResult(jogStatus, 'refused', `jog released: the controller is ${r.state}`);
    }
  }

  let filesLoaded = false;
  function onLink(connected) {
    if (connected && !filesLoaded) { filesLoaded = true; refreshFiles(); }
    if (!connected) filesLoaded = false;
  }
  function onDisconnect() { filesLoaded = false; }

  /** No live data (why: what is lost): nothing shown is current, so no validated move may go and no jog is renewed. */
  function onDataLoss(why) {
    invalidate(`no live data (${why}): Go is disabled; validate again once live data return`);
    if (previewed) resetPreview(`no live data (${why}): Apply is disabled; preview again once live data return`);
    if (jog) {
      releaseJog(true);   // the release queues behind any renewal held up on the way: nothing starts the jog again
      jogSerial += 1;     // its reply must not stand in for why it was released
      setResult(jogStatus, 'refused', `jog released: no live data (${why}); the page sent the release and stopped renewing it (the service's deadman brakes it should the release not arrive)`);
    }
  }

  return { onRecord, onLink, onDisconnect, onDataLoss, releaseJog, withdrawnBy };
}
