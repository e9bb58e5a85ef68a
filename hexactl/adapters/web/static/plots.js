// Telemetry history (at most 300 s at 50 Hz) and its uPlot charts.
import uPlot from './vendor/uPlot.esm.js';

const AXES = ['x', 'y', 'z', 'roll', 'pitch', 'yaw'];
const UNITS = ['mm', 'mm', 'mm', 'deg', 'deg', 'deg'];
const MAX_SECONDS = 300;
const CAPACITY = MAX_SECONDS * 50 + 500;   // 300 s at 50 Hz, with slack for a faster stream
const TRIM = 500;                          // drop records from the front in chunks
const GAP_FACTOR = 3;                      // a wait this many record intervals long (and ≥ MIN_GAP_S) is an outage
const MIN_GAP_S = 0.5;

const num = (v) => (typeof v === 'number' && Number.isFinite(v) ? v : null);

/** Columnar history of the records: plain arrays, trimmed in chunks. */
export class History {
  constructor() { this.clear(); }

  clear() {
    this.interval = 0;     // between the last two records that came without an outage between them, s
    this.t = [];
    this.pc = AXES.map(() => []);
    this.pm = AXES.map(() => []);
    this.sp = AXES.map(() => []);
    this.fb = AXES.map(() => []);
    this.lat = [];
    this.comp = [];
  }

  get length() { return this.t.length; }

  push(r) {
    const t = num(r.t);
    if (t === null) return;
    const n = this.t.length;
    if (n && t < this.t[n - 1]) this.clear();          // the service restarted: its clock began again
    else if (n && t === this.t[n - 1]) return;           // the same record twice
    else if (n && t - this.t[n - 1] > Math.max(MIN_GAP_S, GAP_FACTOR * this.interval)) {
      this.pushGap((t + this.t[n - 1]) / 2);            // no records came: break the lines, never draw a move across
    } else if (n) this.interval = t - this.t[n - 1];     // an outage's length is no record interval
    this.t.push(t);
    for (let i = 0; i < 6; i++) {
      this.pc[i].push(num(r.pose_command?.[i]));
      this.pm[i].push(num(r.pose_measured?.[i]));
      this.sp[i].push(num(r.leg_setpoints?.[i]));
      this.fb[i].push(num(r.leg_feedback?.[i]));
    }
    this.lat.push(num(r.loop?.lateness_us?.p99));
    this.comp.push(num(r.loop?.compute_us?.p99));
    const last = this.t.length - 1;
    if (this.t.length > CAPACITY || this.t[last] - this.t[0] > MAX_SECONDS + 2) this.trim();
  }

  /** A row of no values at ``t``: the charts' lines break there (spanGaps false). */
  pushGap(t) {
    this.t.push(t);
    for (let i = 0; i < 6; i++) { this.pc[i].push(null); this.pm[i].push(null); this.sp[i].push(null); this.fb[i].push(null); }
    this.lat.push(null);
    this.comp.push(null);
  }

  trim() {
    const tEnd = this.t[this.t.length - 1];
    let k = Math.max(this.t.length - CAPACITY + TRIM, 0);
    while (k < this.t.length && tEnd - this.t[k] > MAX_SECONDS) k++;
    if (k <= 0) return;
    const cut = (a) => a.splice(0, k);
    cut(this.t); this.pc.forEach(cut); this.pm.forEach(cut); this.sp.forEach(cut); this.fb.forEach(cut);
    cut(this.lat); cut(this.comp);
  }

  /** Index of the first record with t >= t0. */
  indexFrom(t0) {
    let lo = 0, hi = this.t.length;
    while (lo < hi) { const mid = (lo + hi) >> 1; if (this.t[mid] < t0) lo = mid + 1; else hi = mid; }
    return lo;
  }

  toCSV() {
    const head = ['t_s',
      ...AXES.map((a, i) => `pose_command_${a}_${UNITS[i]}`),
      ...AXES.map((a, i) => `pose_measured_${a}_${UNITS[i]}`),
      ...[1, 2, 3, 4, 5, 6].map((l) => `setpoint_${l}_mm`),
      ...[1, 2, 3, 4, 5, 6].map((l) => `feedback_${l}_mm`),
      'lateness_p99_us', 'compute_p99_us'];
    const lines = [head.join(',')];
    const cell = (v) => (v === null || v === undefined ? '' : String(v));
    for (let k = 0; k < this.t.length; k++) {
      if (this.pc[0][k] === null && this.sp[0][k] === null && this.lat[k] === null) continue;  // a gap's row
      const row = [this.t[k]];
      for (let i = 0; i < 6; i++) row.push(this.pc[i][k]);
      for (let i = 0; i < 6; i++) row.push(this.pm[i][k]);
      for (let i = 0; i < 6; i++) row.push(this.sp[i][k]);
      for (let i = 0; i < 6; i++) row.push(this.fb[i][k]);
      row.push(this.lat[k], this.comp[k]);
      lines.push(row.map(cell).join(','));
    }
    return lines.join('\n') + '\n';
  }
}

const AXIS_STYLE = {
  stroke: '#8b98a9',
  grid: { stroke: 'rgba(139,152,169,0.12)', width: 1 },
  ticks: { stroke: 'rgba(139,152,169,0.25)', width: 1 },
  font: '11px system-ui, sans-serif',
};

function chartOptions(width, series, yLabel, windowS) {
  return {
    width, height: 170,
    pxAlign: 0,
    cursor: { drag: { x: false, y: false }, points: { size: 5 } },
    scales: { x: { time: false, range: () => [-windowS(), 0] } },
    legend: { live: true },
    axes: [
      { ...AXIS_STYLE, label: 's (0 = newest)', labelSize: 14, labelFont: '11px system-ui, sans-serif', size: 30 },
      { ...AXIS_STYLE, label: yLabel, labelSize: 14, labelFont: '11px system-ui, sans-serif', size: 56 },
    ],
    series: [{ label: 't' }, ...series],
  };
}

const series = (label, stroke, extra = {}) => ({ label, stroke, width: 1.5, spanGaps: false, points: { show: false },
  value: (u, v) => (v === null || v === undefined ? '–' : v.toFixed(Math.abs(v) >= 100 ? 1 : 3)), ...extra });

/** The three charts, redrawn from the history at most a few times a second. */
export class Plots {
  constructor(history, els) {
    this.history = history;
    this.els = els;
    this.windowS = 30;
    this.axis = 2;
    this.leg = 0;
    this.paused = false;
    this.dirty = false;
    this.lastDraw = 0;
    const w = (el) => Math.max(200, el.clientWidth || 300);
    const empty = (n) => Array.from({ length: n }, () => []);
    const win = () => this.windowS;
    this.pose = new uPlot(chartOptions(w(els.pose), [
      series('commanded', '#4f9dff'), series('measured', '#e879f9', { dash: [5, 3] })], 'mm', win), empty(3), els.pose);
    this.legs = new uPlot(chartOptions(w(els.legs), [
      series('set-point', '#3ecf6e'), series('feedback', '#f0b429', { dash: [5, 3] })], 'sensor mm', win), empty(3), els.legs);
    this.loop = new uPlot(chartOptions(w(els.loop), [
      series('lateness p99', '#f87171'), series('compute p99', '#60a5fa')], 'µs', win), empty(3), els.loop);
    this.charts = [[this.pose, els.pose], [this.legs, els.legs], [this.loop, els.loop]];
    const ro = new ResizeObserver(() => {
      for (const [chart, el] of this.charts) {
        const width = Math.max(200, el.clientWidth);
        if (Math.abs(width - chart.width) > 1) chart.setSize({ width, height: 170 });
      }
    });
    this.charts.forEach(([, el]) => ro.observe(el));
  }

  setAxis(i) { this.axis = i; this.dirty = true; this.redraw(true); }
  setLeg(i) { this.leg = i; this.dirty = true; this.redraw(true); }
  setWindow(s) { this.windowS = s; this.dirty = true; this.redraw(true); }
  setPaused(p) { this.paused = p; if (!p) { this.dirty = true; this.redraw(true); } }

  /** Called from the animation frame: redraw at most every 200 ms, never while paused. */
  maybeRedraw(now) {
    if (this.paused || !this.dirty) return;
    if (now - this.lastDraw < 200) return;
    this.redraw();
  }

  redraw(force = false) {
    if (this.paused && !force) return;
    this.lastDraw = performance.now();
    this.dirty = false;
    const h = this.history;
    const n = h.length;
    if (!n) return;
    const tEnd = h.t[n - 1];
    const k = h.indexFrom(tEnd - this.windowS);
    const x = new Array(n - k);
    for (let j = k; j < n; j++) x[j - k] = h.t[j] - tEnd;
    const sl = (a) => a.slice(k, n);
    const a = this.axis, l = this.leg;
    this.pose.setData([x, sl(h.pc[a]), sl(h.pm[a])]);
    this.legs.setData([x, sl(h.sp[l]), sl(h.fb[l])]);
    this.loop.setData([x, sl(h.lat), sl(h.comp)]);
  }
}

export { AXES, UNITS };
