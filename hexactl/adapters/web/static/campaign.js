// The calibration campaign view: a running campaign's progress and sentences, and a
// finished campaign's report (parameters with σ, the fit, each test motion's largest
// errors before and after), from telemetry's `campaign` field (the API's `progress`
// command, sent by `hexactl campaign` and `hexactl demo`).

const $ = (id) => document.getElementById(id);
const num = (v, digits) => (typeof v === 'number' && Number.isFinite(v) ? v.toFixed(digits) : '–');

function cell(row, text, cls) {
  const td = row.insertCell();
  td.textContent = text;
  if (cls) td.className = cls;
  return td;
}

function table(head, rows) {
  const t = document.createElement('table');
  t.className = 'campaign-table';
  const h = t.createTHead().insertRow();
  for (const name of head) {
    const th = document.createElement('th');
    th.textContent = name;
    h.appendChild(th);
  }
  const body = t.createTBody();
  for (const values of rows) {
    const row = body.insertRow();
    for (const value of values) cell(row, value);
  }
  return t;
}

function parameterRows(parameters) {
  // B1.x … P6.z and zero1 … in mm; scale1 … dimensionless, shown in ppm.
  return parameters.map((p) => {
    const scale = p.name.startsWith('scale');
    const factor = scale ? 1e6 : 1;
    const unit = scale ? 'ppm' : 'mm';
    const sigma = p.sigma == null ? 'undetermined' : num(p.sigma * factor, scale ? 1 : 4);
    return [p.name, num(p.value * factor, scale ? 1 : 4), sigma, unit];
  });
}

function renderReport(report) {
  const box = $('campaign-report');
  box.replaceChildren();
  if (!report) { box.hidden = true; return; }
  box.hidden = false;
  const verdict = document.createElement('p');
  verdict.className = `result ${report.improved ? 'valid' : 'refused'}`;
  verdict.textContent = `${report.improved ? 'improved' : 'NOT improved'}: calibration ${report.calibration_id} ` +
    `(${report.method}, ${report.postures} postures); fit residual RMS ${num(report.residual_rms_mm, 4)} mm ` +
    `(noise model ${num(report.expected_rms_mm, 4)} mm), ${report.fit}`;
  box.appendChild(verdict);
  box.appendChild(table(['test motion', 'before mm', 'before °', 'after mm', 'after °'],
    report.validation.map((m) => [m.motion, num(m.before_position_mm, 3), num(m.before_orientation_deg, 4),
      num(m.after_position_mm, 3), num(m.after_orientation_deg, 4)])));
  for (const warning of report.warnings || []) {
    const p = document.createElement('p');
    p.className = 'result refused small';
    p.textContent = `warning: ${warning}`;
    box.appendChild(p);
  }
  const details = document.createElement('details');
  const summary = document.createElement('summary');
  summary.textContent = `${report.parameters.length} parameters with 1σ`;
  details.appendChild(summary);
  details.appendChild(table(['parameter', 'value', '1σ', 'unit'], parameterRows(report.parameters)));
  box.appendChild(details);
}

export function setupCampaign() {
  let shown = '';
  let shownReport = '';
  return function update(campaign) {
    if (!campaign || typeof campaign !== 'object') {
      if (shown !== 'none') {
        shown = 'none';
        $('campaign-progress').textContent = 'no campaign has reported to this service';
        $('campaign-bar').value = 0;
        $('campaign-said').replaceChildren();
        renderReport(null);
      }
      return;
    }
    const { age_s: age, report, ...rest } = campaign;
    const key = JSON.stringify(rest);
    if (key !== shown) {
      shown = key;
      const total = Number(campaign.total) || 0;
      $('campaign-progress').textContent =
        `${campaign.title || 'campaign'} ${campaign.done}/${total}${campaign.label ? ` · ${campaign.label}` : ''}`;
      $('campaign-bar').value = total ? Math.min(1, campaign.done / total) : 0;
      const said = $('campaign-said');
      said.replaceChildren(...(campaign.said || []).map((text) => {
        const li = document.createElement('li');
        li.textContent = text;
        return li;
      }));
    }
    const reportKey = JSON.stringify(report ?? null);
    if (reportKey !== shownReport) {
      shownReport = reportKey;
      renderReport(report ?? null);
    }
    $('campaign-age').textContent = typeof age === 'number' ? `last heard ${age.toFixed(0)} s ago` : '';
  };
}
