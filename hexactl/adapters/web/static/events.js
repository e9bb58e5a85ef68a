// The Events panel: the control loop's recent events (telemetry's `events`, docs/api.md),
// newest first, each with how long before the newest record it happened, its code, its
// message and who sent the command behind it. The page keeps the last EVENTS_KEPT it has
// seen, so an event stays listed after it has left the records' window of eight. Events
// are numbered (`seq`): when a record's first is more than one past the last the page
// took (a burst of more than eight, or records the page did not get), it asks the
// service for those after it (the `events` request), so that the burst is listed whole.
// A new service run (a restart) is told by the records' t going back (another clock) or,
// on the same host, whose monotonic clock goes on, by the event numbers going back; the
// page then asks for the new run's events from its first, and says what it missed.
//
// Cheap at 50 records a second: a record whose newest event is the one seen last costs a
// comparison; the list is built again only when an event is new, and the "ago" texts are
// rewritten at most every AGO_EVERY_MS. Text goes in with textContent only: senders are
// names clients chose.

const $ = (id) => document.getElementById(id);

export const EVENTS_KEPT = 64;  // as many as the service keeps: a burst it sends is listed whole
const LINES_KEPT = EVENTS_KEPT + 1;  // … with the events_missed line saying how many came before them
const AGO_EVERY_MS = 500;
const ASK_AGAIN_MS = 1000;  // a gap whose request failed is asked for again with a record at least this much later
const ASK_TRIES = 3;        // then the page says it could not get them

// The loop's daily work, as the service's log counts it (INFO, not WARNING:
// hexactl/application/safety_log.py, _ROUTINE_EVENTS): these codes, and those starting
// with one of ROUTINE_PREFIXES. Every other code is shown as a warning: an E-stop, a
// fault's code (heartbeat_lost, leg_lock_projection, …), command_link_silent, a guard's
// clamp, and any code this page does not know.
const ROUTINE_CODES = new Set([
  'enabled', 'disabled', 'stop', 'reset', 'move', 'pause', 'resume', 'abort',
  'leg_locked', 'leg_unlocked', 'calibration_swapped', 'command_refused', 'command_link_heard', 'frames_set',
]);
const ROUTINE_PREFIXES = ['sequence_', 'jog_', 'stream_', 'wave_'];

/** Whether an event of this code stands out as a warning (see ROUTINE_CODES). */
export function isWarning(code) {
  return !(ROUTINE_CODES.has(code) || ROUTINE_PREFIXES.some((prefix) => code.startsWith(prefix)));
}

/** "4.2 s ago", "37 s ago", "5 min 3 s ago", "2 h 10 min ago", "3 d 4 h ago" for an age in seconds. */
export function agoText(seconds) {
  if (!Number.isFinite(seconds)) return '';
  const s = Math.max(0, seconds);
  if (s < 10) return `${s.toFixed(1)} s ago`;
  if (s < 60) return `${Math.floor(s)} s ago`;
  if (s < 3600) return `${Math.floor(s / 60)} min ${Math.floor(s % 60)} s ago`;
  if (s < 86400) return `${Math.floor(s / 3600)} h ${Math.floor((s % 3600) / 60)} min ago`;
  return `${Math.floor(s / 86400)} d ${Math.floor((s % 86400) / 3600)} h ago`;
}

const finite = (v) => typeof v === 'number' && Number.isFinite(v);

/** {number, t, code, message, sender} of a record's event, or null for one the page cannot show. */
function clean(e) {
  if (!e || typeof e !== 'object' || !finite(e.t) || typeof e.code !== 'string') return null;
  return {
    number: Number.isSafeInteger(e.seq) ? e.seq : null,
    t: e.t,
    code: e.code,
    message: typeof e.message === 'string' ? e.message : '',
    sender: typeof e.sender === 'string' && e.sender !== '' ? e.sender : null,
  };
}

const sameEvent = (a, b) => a.t === b.t && a.code === b.code && a.message === b.message && a.sender === b.sender;

/**
 * The panel (#events). Returns hooks the app calls: onRecord(record) for every telemetry
 * record received, draw(now) from the draw loop; entries() what the panel lists.
 * askAfter(number) sends the service's `events` request for the events numbered after
 * `number` and resolves with its reply (ok or not).
 */
export function setupEvents(askAfter) {
  const list = $('events');
  const kept = [];          // newest first: {t, code, message, sender, warning, key, seq, run, li, ago}
  const keys = new Set();   // kept's keys: JSON of [t, code, message, sender]
  let newest = null;        // the newest event of the last record taken in, as received
  let recordT = null;       // the newest record's t (s, the service's clock)
  let run = 0;              // +1 for each new service run: its clock or its event numbers went back
  let seq = 0;
  let lastNumber = 0;       // the newest event number taken in from this run (0: none)
  let recordNumber = 0;     // the newest event number a record of this run carried (records come in order:
                            // it never goes back within a run, where a reply's events may be newer than a record's)
  let fromStart = false;    // a new run began: its events are asked for from its first
  let asking = false;       // an `events` request for a gap is under way
  let askNext = null;       // the number after which a gap opened while it was: asked for once it is answered
  let askAgain = null;      // the number after which a gap's request failed (no reply in time, the service busy)
  let askAgainAt = 0;       // performance.now() from which a record asks for it again
  let failedAsks = 0;       // requests that failed in a row
  let dirty = false;
  let agoAt = -Infinity;    // performance.now() of the last "ago" update (only to limit their rate)
  let agoFor = null;        // the record t they were computed at

  /** A new service run: what the page knew of the last one's numbers no longer holds. */
  function newRun() {
    run += 1;
    lastNumber = 0;
    recordNumber = 0;
    askNext = null;
    askAgain = null;
    failedAsks = 0;
    fromStart = true;
  }

  function onRecord(r) {
    if (finite(r.t)) {
      if (recordT !== null && r.t < recordT) newRun();   // another clock: a service elsewhere, or a reboot
      recordT = r.t;
    }
    const events = Array.isArray(r.events) ? r.events : [];
    const last = events.length ? clean(events[events.length - 1]) : null;
    // The same host's monotonic clock goes on over a restart; the new service numbers its events from 1.
    if (last !== null && last.number !== null) {
      if (last.number < recordNumber) newRun();
      recordNumber = Math.max(recordNumber, last.number);
    }
    if (askAgain !== null && !asking && performance.now() >= askAgainAt) {
      const again = askAgain;
      askAgain = null;
      askFrom(again);
    }
    if (last === null || (newest !== null && sameEvent(last, newest))) return;
    newest = last;
    const first = clean(events[0]);
    if (first !== null && first.number !== null) {
      if (fromStart) {
        fromStart = false;
        if (first.number > 1) askFrom(0);   // the new run's events before this record's
      } else if (lastNumber > 0 && first.number > lastNumber + 1) {
        askFrom(lastNumber);
      }
    }
    take(events);
  }

  /** The events numbered after `after` from the service: those the records skipped. A gap
   * that opens while a request is under way is asked for once it is answered (from the
   * earliest such gap: the reply has every event after it that the service still keeps).
   * A request that fails (no reply within the page's time-out on a busy host, the link
   * down) is asked again, merged with any gap that opened meanwhile, with a later record;
   * after ASK_TRIES failures in a row a warning line says which events the page could not
   * get, and why. */
  async function askFrom(after) {
    if (!askAfter) return;
    if (asking) {
      askNext = askNext === null ? after : Math.min(askNext, after);
      return;
    }
    asking = true;
    const asked = run;
    try {
      const reply = await askAfter(after);
      if (asked !== run) return;
      if (!reply || reply.ok !== true) {
        const from = Math.min(askNext ?? after, after);
        askNext = null;
        failedAsks += 1;
        if (failedAsks < ASK_TRIES) {
          askAgain = Math.min(askAgain ?? from, from);
          askAgainAt = performance.now() + ASK_AGAIN_MS;
        } else {
          failedAsks = 0;
          take([{ t: recordT ?? 0, code: 'events_missed', sender: null,
                  message: `the events after number ${from} could not be fetched (${reply?.error?.code ?? 'no reply'}, `
                           + `${ASK_TRIES} times): the service's log has them` }]);
        }
        return;
      }
      failedAsks = 0;
      const events = Array.isArray(reply.events) ? reply.events : [];
      if (Number.isSafeInteger(reply.missed) && reply.missed > 0 && finite(events[0]?.t ?? reply.t)) {
        // taken first: listed just below (before) the oldest event the service still had
        take([{ t: events[0]?.t ?? reply.t, code: 'events_missed', sender: null,
                message: `${reply.missed} events came and went before the page could ask (the service's log has them)` }]);
      }
      take(events);
    } finally {
      asking = false;
      if (askNext !== null) {
        const next = askNext;
        askNext = null;
        askFrom(next);
      }
    }
  }

  function take(events) {
    for (const raw of events) {
      const e = clean(raw);
      if (e === null) continue;
      if (e.number !== null) lastNumber = Math.max(lastNumber, e.number);
      const key = JSON.stringify([e.t, e.code, e.message, e.sender]);
      if (keys.has(key)) continue;
      keys.add(key);
      kept.push({ ...e, warning: isWarning(e.code), key, seq: seq++, run, li: null, ago: null });
      dirty = true;
    }
    if (!dirty) return;
    kept.sort((a, b) => (b.run - a.run) || (b.t - a.t) || (b.seq - a.seq));
    while (kept.length > LINES_KEPT) keys.delete(kept.pop().key);
  }

  function line(e) {
    const li = document.createElement('li');
    li.className = e.warning ? 'warning' : 'routine';
    li.dataset.code = e.code;
    li.dataset.t = String(e.t);
    const ago = document.createElement('span'); ago.className = 'ago';
    ago.title = `t = ${e.t.toFixed(3)} s on the service's clock`;
    const code = document.createElement('span'); code.className = 'code'; code.textContent = e.code;
    const message = document.createElement('span'); message.className = 'msg'; message.textContent = e.message;
    li.append(ago, ' ', code, ' ', message);
    if (e.sender !== null) {
      const by = document.createElement('span'); by.className = 'by'; by.textContent = `by ${e.sender}`;
      li.append(' ', by);
    }
    e.li = li;
    e.ago = ago;
    return li;
  }

  function updateAgo() {
    for (const e of kept) {
      // an event of an earlier clock (the service restarted on another one) has no age on this one
      const text = e.run === run ? agoText(recordT - e.t) : 'before the service restarted';
      if (e.ago.textContent !== text) e.ago.textContent = text;
    }
  }

  /** From the draw loop: the list again if an event is new; the "ago" texts at most every AGO_EVERY_MS. */
  function draw(now) {
    if (dirty) {
      dirty = false;
      list.replaceChildren(...kept.map((e) => e.li ?? line(e)));
      agoAt = -Infinity;   // the new lines get their "ago" now
      agoFor = null;
    }
    if (recordT !== null && recordT !== agoFor && now - agoAt >= AGO_EVERY_MS) {
      agoAt = now;
      agoFor = recordT;
      updateAgo();
    }
  }

  /** What the panel lists, newest first (for tests and tools). */
  function entries() {
    return kept.map((e) => ({
      t: e.t, code: e.code, message: e.message, sender: e.sender, warning: e.warning,
      ago: e.ago ? e.ago.textContent : '',
    }));
  }

  return { onRecord, draw, entries };
}
