// The result view of a convergence study (job kind "study"): the reference solution, the
// error table with observed orders, the least-squares orders, and the server's report SVG
// (error vs h or k with slope guides; error vs time). Nothing is drawn here: the report is
// the server's, embedded as an <img>. Summary contract:
//   {kind: "study", vary: "h"|"k"|"hk", reference: {h, k, w_V, zeta_Z0, seconds},
//    rows: [{h, k, err_w, err_zeta, order_w, order_zeta (null on the first row), unknowns,
//            steps, seconds}], lsq_order_w, lsq_order_zeta}
// or, for a target study, {kind: "target", target_error, quantity, chosen, attempts,
//    error_model, pilots, safety_factor, seconds} (showTarget), or for a parameter sweep
//    {kind: "sweep", name, mode, vary: [{pointer, values}], rows: [{member, values, w_V, u_V,
//     zeta_L2, zeta_min, min_zeta, slip_nodes, max_slip_speed, steps, wall_s, cached}],
//     computed, seconds} (showSweep, its plot the server's /jobs/{id}/plot.svg), or for an
//    adaptive study {kind: "adapt", name, quantity, target, theta, max_nodes, reached,
//    stopped, cycles: [Row], uniform: [Row], reference: Row (optional), summary,
//    final_mesh: {id, file}} with Row {nodes, cells, unknowns, generation, estimate,
//    estimate_abs, time_share, error (optional), marked (optional), seconds} (showAdapt).

import * as api from './api.js';
import { el, fmt, fmtStep, fmtSeconds } from './util.js';

/**
 * The paper's own Tables 1 and 2 (Han, Jureczka & Ochal 2020), by the level that varies:
 * [err w, order w, err ζ, order ζ]. Shown beside this service's values for the two study
 * presets, as README and the Python example do (this scheme's errors differ from the
 * paper's; its orders agree).
 */
const PAPER = {
  'paper-table-1': {
    '1/2': [3.4889e-1, null, 8.7595e-2, null],
    '1/4': [2.2027e-1, 0.664, 4.3672e-2, 1.004],
    '1/8': [1.2745e-1, 0.789, 1.7248e-2, 1.340],
    '1/16': [7.2811e-2, 0.808, 6.1124e-3, 1.497],
    '1/32': [3.9967e-2, 0.865, 2.1316e-3, 1.520],
  },
  'paper-table-2': {
    '1/2': [8.5393e-2, null, 4.0107e-1, null],
    '1/4': [6.8195e-2, 0.324, 5.6124e-2, 2.837],
    '1/8': [3.2105e-2, 1.087, 2.2501e-2, 1.319],
    '1/16': [1.4883e-2, 1.109, 8.4583e-3, 1.412],
    '1/32': [7.0551e-3, 1.077, 4.3778e-3, 0.950],
  },
};

/**
 * A study's table: it fits the panel on a wide screen, and on a narrow one scrolls sideways
 * inside its frame (focusable, so the keyboard scrolls it too) and says so.
 */
function scrollingTable(id, label, heads, rows) {
  return el('div', { class: 'table-wrap', tabindex: '0', role: 'region', 'aria-label': label },
    el('table', { class: 'study', id },
      el('caption', { class: 'scroll-note' }, 'Scroll sideways for every column →'),
      el('thead', {}, el('tr', {}, heads.map((h) => el('th', { scope: 'col' }, h)))),
      el('tbody', {}, rows)));
}

/**
 * A study's report: on a phone it keeps its own size (its 11 px labels would shrink to 4 px
 * at the screen's width) and scrolls sideways in its frame, as the table does.
 */
function scrollingReport(img) {
  return el('div', { class: 'report-wrap', id: 'report-wrap', tabindex: '0', role: 'region', 'aria-label': 'report (scrolls sideways on a narrow screen)' },
    el('p', { class: 'scroll-note' }, 'Scroll sideways for the whole report →'),
    img);
}

/** A download link that works with a key and says its size once known. */
function sized(a) {
  api.sizeInto(a, a.textContent, a.getAttribute('href'));
  return api.keyedLink(a);
}

/** Why an adaptive study's cycles ended, in words (its summary's `stopped`). */
const STOPPED = {
  target: 'the estimate met the target',
  max_nodes: 'the next mesh would have had more than max_nodes nodes',
  max_cycles: 'the largest number of cycles (max_cycles) ran',
  time_step: 'the estimate\'s time part dominates it: refining the mesh no longer reduces it, a smaller time step k would',
  memory: 'the next mesh\'s run would not fit the memory limit of a job',
  nothing_to_refine: 'every error indicator is zero, so refining cannot change the estimate',
};

/** The sentence on an adaptive study's outcome: target reached or not, and why it stopped. */
function adaptOutcome(s) {
  const cycles = (s.cycles || []).length;
  const last = s.cycles?.[cycles - 1];
  const why = STOPPED[s.stopped] || s.stopped;
  return `Target ${fmt(s.target)} for the relative estimate of ${s.quantity || 'w'} `
    + `${s.reached ? 'reached' : 'not reached'} after ${cycles} ${cycles === 1 ? 'cycle' : 'cycles'} `
    + `(last estimate ${fmt(last?.estimate)}, ${last?.nodes ?? '–'} nodes; θ = ${s.theta}, at most ${s.max_nodes} nodes): `
    + `the cycles stopped because ${why}.`;
}

export class StudyView {
  constructor(root) {
    this.root = root;
    this.job = null;
  }

  async open(job) {
    this.close();
    this.job = job;
    const id = job.id;
    this.root.dataset.state = 'loading';
    this.root.dataset.job = id;
    this.root.replaceChildren(el('p', { class: 'hint' }, 'Loading the study…'));
    let s;
    try {
      s = await api.summary(id);
    } catch (e) {
      if (this.job !== job) return;
      this.root.dataset.state = 'error';
      this.root.replaceChildren(el('p', { class: 'error' }, `Cannot load the study: ${e.message}`));
      return;
    }
    if (this.job !== job) return;
    const report = job.links?.report || `/jobs/${id}/report.svg`;
    if (s.kind === 'target') {
      this.showTarget(job, s, report);
      return;
    }
    if (s.kind === 'sweep') {
      this.showSweep(job, s);
      return;
    }
    if (s.kind === 'adapt') {
      this.showAdapt(job, s, report);
      return;
    }
    const ref = s.reference || {};
    const vary = s.vary || '';
    const order = (x) => (x === null || x === undefined ? '–' : Number(x).toFixed(3));
    const num = (x, cls = '') => el('td', { class: `num ${cls}`.trim() }, x);
    const paper = PAPER[job.scene || s.name];
    const paperRow = (r) => paper?.[fmtStep(vary === 'k' ? r.k : r.h)] || [null, null, null, null];
    const rows = (s.rows || []).map((r) => {
      const p = paperRow(r);
      const ours = [num(fmt(r.err_w)), num(order(r.order_w))];
      const oursZ = [num(fmt(r.err_zeta)), num(order(r.order_zeta))];
      const theirs = (e, o) => (paper ? [num(fmt(e), 'paper'), num(order(o), 'paper')] : []);
      return el('tr', {},
        num(fmtStep(r.h)), num(fmtStep(r.k)),
        ...ours, ...theirs(p[0], p[1]),
        ...oursZ, ...theirs(p[2], p[3]),
        num(r.unknowns ?? '–'), num(r.steps ?? '–'), num(fmtSeconds(r.seconds)));
    });
    const heads = paper
      ? ['h', 'k', 'err w', 'order', 'paper err w', 'paper order', 'err ζ', 'order', 'paper err ζ', 'paper order', 'unknowns', 'steps', 'time']
      : ['h', 'k', 'err w', 'order', 'err ζ', 'order', 'unknowns', 'steps', 'time'];
    const img = el('img', { class: 'report', alt: 'error against the mesh size or time step, and error over time' });
    this.root.replaceChildren(
      el('div', { class: 'view-head' },
        el('h2', {}, job.scene || 'study', ' ', el('small', {}, id.slice(0, 8))),
        el('nav', { class: 'downloads', 'aria-label': 'downloads' },
          sized(el('a', { id: 'dl-summary', href: `/jobs/${id}/summary`, download: `study-${id.slice(0, 8)}.json` }, 'summary JSON')),
          sized(el('a', { id: 'dl-report', href: report, download: `report-${id.slice(0, 8)}.svg` }, 'report SVG')))),
      el('p', { class: 'run-info' },
        `Convergence in ${vary === 'hk' ? 'h = k' : vary || '?'} against the reference h = ${fmtStep(ref.h)}, k = ${fmtStep(ref.k)} `,
        `(|w|_V = ${fmt(ref.w_V, 10)}, |ζ|_Z0 = ${fmt(ref.zeta_Z0, 10)}, ${fmtSeconds(ref.seconds)}). `,
        `Least-squares orders: w ${order(s.lsq_order_w)}, ζ ${order(s.lsq_order_zeta)}.`),
      ...(paper ? [el('p', { class: 'run-info', id: 'paper-note' },
        'The paper\'s own values are beside ours: this scheme\'s errors differ from the paper\'s, its orders agree (see the user guide, "Reproduce the paper").')] : []),
      scrollingTable('study-table', 'error table (scrolls sideways)', heads, rows),
      scrollingReport(img),
    );
    api.keyedImage(img, report);
    this.root.dataset.state = 'ready';
  }

  /**
   * A target study (summary kind "target"): the chosen (h, k), predicted and estimated error,
   * predicted and measured time, the fitted models, every attempt, the work–precision report,
   * and the chosen run's files (archive, PVD) served like a simulation's.
   */
  showTarget(job, s, report) {
    const id = job.id;
    const c = s.chosen || {};
    const m = s.error_model || {};
    const order = (x) => (x === null || x === undefined ? '–' : Number(x).toFixed(3));
    const num = (x) => el('td', { class: 'num' }, x);
    const rows = (s.attempts || []).map((a) => el('tr', {},
      num(fmtStep(a.h)), num(fmtStep(a.k)), num(a.unknowns ?? '–'), num(a.steps ?? '–'),
      num(fmt(a.predicted_error)), num(fmt(a.estimated_error)),
      num(a.check_passed ? 'passed' : 'failed'),
      num(fmtSeconds(a.predicted_seconds)), num(fmtSeconds(a.seconds))));
    const img = el('img', { class: 'report', alt: 'work–precision: predicted frontier, pilot runs and the chosen run' });
    this.root.replaceChildren(
      el('div', { class: 'view-head' },
        el('h2', {}, s.name || job.scene || 'target study', ' ', el('small', {}, id.slice(0, 8))),
        el('nav', { class: 'downloads', 'aria-label': 'downloads' },
          api.keyedLink(el('a', { href: `/jobs/${id}/summary`, download: `target-${id.slice(0, 8)}.json` }, 'summary JSON')),
          api.keyedLink(el('a', { href: report, download: `report-${id.slice(0, 8)}.svg` }, 'report SVG')),
          ...(s.final_mesh?.file ? [sized(el('a', { id: 'dl-final-mesh', href: s.final_mesh.file, download: `target-${id.slice(0, 8)}.msh` }, 'adaptive mesh (MSH)'))] : []),
          api.keyedLink(el('a', { href: `/jobs/${id}/archive.tar`, download: `contact-sim-${id}.tar` }, 'chosen run (VTU archive)')))),
      el('p', { class: 'run-info', id: 'target-choice' },
        `Target ${s.target_error} in ${s.quantity}: h = ${fmtStep(c.h)}, k = ${fmtStep(c.k)}`,
        c.refine !== undefined ? ` (refine ${c.refine})` : '',
        `, predicted error ${fmt(c.predicted_error)}, estimated ${fmt(c.estimated_error)} `,
        `(check ${c.check_passed ? 'passed' : 'failed'}); predicted ${fmtSeconds(c.predicted_seconds)}, `,
        `measured ${fmtSeconds(c.seconds)}; whole study ${fmtSeconds(s.seconds)}.`,
        // The model's prediction may lie above the target while the run's own (2h, 2k)
        // estimate, which decides, lies below it: say so rather than leave it unexplained.
        c.predicted_error > s.target_error && c.check_passed
          ? ` The fitted model predicted more than the target here; the run's own (2h, 2k) error estimate, ${fmt(c.estimated_error)}, is below it, and that check decides.`
          : ''),
      // Which meshes the chosen run is on: the uniform level, or an adaptive mesh with fewer
      // nodes and an estimate no larger (target.meshes "auto"), and why.
      el('p', { class: 'run-info', id: 'target-meshes' },
        `Meshes: ${s.meshes?.taken || 'uniform'}${s.meshes?.reason ? ` (${s.meshes.reason})` : ''}.`),
      el('p', { class: 'run-info', id: 'target-fit' },
        `Error model ${fmt(m.h?.coefficient)}·h^${order(m.h?.order)} + ${fmt(m.k?.coefficient)}·k^${order(m.k?.order)} `,
        `from ${(s.pilots || []).length} pilot runs; safety factor ${s.safety_factor}.`),
      el('div', { class: 'table-wrap', tabindex: '0', role: 'region', 'aria-label': 'chosen runs (scrolls sideways)' },
        el('table', { class: 'study', id: 'target-table' },
          el('thead', {}, el('tr', {}, ['h', 'k', 'unknowns', 'steps', 'predicted error', 'estimated error', 'check', 'predicted time', 'time']
            .map((h) => el('th', { scope: 'col' }, h)))),
          el('tbody', {}, rows))),
      img,
    );
    api.keyedImage(img, report);
    this.root.dataset.state = 'ready';
  }

  /**
   * An adaptive study (summary kind "adapt"): whether the target was reached and why the
   * cycles stopped, one table row per run (the cycles, the uniform line beside them, the
   * reference), the server's report, the final mesh, and the last cycle's run, served like a
   * simulation's (fields, VTU archive).
   */
  showAdapt(job, s, report) {
    const id = job.id;
    const short = id.slice(0, 8);
    const num = (x) => el('td', { class: 'num' }, x);
    const pct = (x) => (typeof x === 'number' ? `${(100 * x).toFixed(0)} %` : '–');
    // "—" (not "–"): the value does not exist for this run (no reference, or the last cycle
    // marks nothing), rather than a number that failed to come.
    const optional = (x, f) => (x === null || x === undefined ? '—' : f(x));
    const row = (label, r) => el('tr', {},
      el('th', { scope: 'row' }, label),
      num(String(r.nodes)), num(String(r.unknowns)), num(String(r.generation)),
      num(fmt(r.estimate)), num(pct(r.time_share)),
      num(optional(r.error, fmt)), num(optional(r.marked, String)),
      num(fmt(r.seconds, 3)));
    const rows = [
      ...(s.cycles || []).map((r, i) => row(`cycle ${i}`, r)),
      ...(s.uniform || []).map((r, i) => row(`uniform h/${2 ** i}`, r)),
      ...(s.reference ? [row('reference', s.reference)] : []),
    ];
    const heads = ['run', 'nodes', 'unknowns', 'deepest bisection', 'estimate', 'time part', 'true error', 'marked', 'time [s]'];
    const mesh = s.final_mesh?.file;
    const img = el('img', { class: 'report', alt: 'estimate and true error against the number of nodes, adaptive cycles beside uniform refinement' });
    this.root.replaceChildren(
      el('div', { class: 'view-head' },
        el('h2', {}, s.name || job.scene || 'adaptive study', ' ', el('small', {}, short)),
        el('nav', { class: 'downloads', 'aria-label': 'downloads' },
          api.keyedLink(el('a', { id: 'dl-summary', href: `/jobs/${id}/summary`, download: `adapt-${short}.json` }, 'summary JSON')),
          api.keyedLink(el('a', { id: 'dl-report', href: report, download: `report-${short}.svg` }, 'report SVG')),
          api.keyedLink(el('a', { id: 'dl-table', href: `/jobs/${id}/summary?format=text`, download: `adapt-${short}.txt` }, 'text table')),
          ...(mesh ? [sized(el('a', { id: 'dl-final-mesh', href: mesh, download: `adapt-${short}.msh` }, 'final mesh (MSH)'))] : []),
          // The last cycle's run is served like a simulation's, as a target study's chosen
          // run is: its fields (with the mesh) and its VTU archive.
          api.keyedLink(el('a', { id: 'dl-last-fields', href: job.links?.fields || `/jobs/${id}/fields?step=last`, download: `adapt-${short}-fields.json` }, 'last cycle\'s fields (JSON)')),
          api.keyedLink(el('a', { href: `/jobs/${id}/archive.tar`, download: `contact-sim-${id}.tar` }, 'last cycle (VTU archive)')))),
      el('p', { class: 'run-info', id: 'adapt-outcome' }, adaptOutcome(s)),
      scrollingTable('adapt-table', 'adaptive runs (scrolls sideways)', heads, rows),
      scrollingReport(img),
    );
    api.keyedImage(img, report);
    this.root.dataset.state = 'ready';
  }

  /**
   * A parameter sweep (summary kind "sweep"): one row per member with its varied values and
   * figures, and the server's plot of a chosen quantity against a chosen varied parameter
   * (one line per value of the others), picked from two menus.
   */
  showSweep(job, s) {
    const id = job.id;
    const pointers = (s.vary || []).map((v) => v.pointer);
    const show = (v) => (typeof v === 'string' ? v : JSON.stringify(v));
    const num = (x) => el('td', { class: 'num' }, x);
    const figures = [
      ['w_V', '|w|_V at T'], ['u_V', '|u|_V at T'], ['zeta_L2', '|ζ|_Z0 at T'], ['zeta_min', 'min ζ at T'],
      ['min_zeta', 'min ζ over the run'], ['slip_nodes', 'slipping Γ3 nodes at T'],
      ['max_slip_speed', 'largest slip speed at T'], ['wall_s', 'wall time'],
    ];
    const rows = (s.rows || []).map((r) => el('tr', {},
      ...pointers.map((p) => num(show(r.values?.[p]))),
      ...figures.map(([k]) => num(k === 'wall_s' ? fmtSeconds(r[k]) : k === 'slip_nodes' ? String(r[k]) : fmt(r[k]))),
      num(r.cached ? 'earlier job' : 'computed')));
    const quantity = el('select', { id: 'sweep-quantity' },
      figures.map(([k, label]) => el('option', { value: k }, label)));
    const against = el('select', { id: 'sweep-against' }, pointers.map((p) => el('option', { value: p }, p)));
    const img = el('img', { class: 'report', id: 'sweep-plot', alt: '' });
    const draw = () => {
      const q = quantity.value;
      const a = against.value;
      img.alt = `${quantity.selectedOptions[0]?.textContent} against ${a}, one line per value of the other parameters`;
      api.keyedImage(img, `/jobs/${id}/plot.svg?quantity=${encodeURIComponent(q)}&against=${encodeURIComponent(a)}`);
    };
    quantity.addEventListener('change', draw);
    against.addEventListener('change', draw);
    this.root.replaceChildren(
      el('div', { class: 'view-head' },
        el('h2', {}, s.name || job.scene || 'sweep', ' ', el('small', {}, id.slice(0, 8))),
        el('nav', { class: 'downloads', 'aria-label': 'downloads' },
          sized(el('a', { id: 'dl-summary', href: `/jobs/${id}/summary`, download: `sweep-${id.slice(0, 8)}.json` }, 'summary JSON')),
          sized(el('a', { id: 'dl-table-csv', href: `/jobs/${id}/table.csv`, download: `sweep-${id.slice(0, 8)}.csv` }, 'table CSV')))),
      el('p', { class: 'run-info', id: 'sweep-info' },
        `${(s.rows || []).length} members (${s.mode}) of ${pointers.join(', ')}: ${s.computed} computed, `,
        `${(s.rows || []).length - s.computed} taken from earlier jobs or equal members; ${fmtSeconds(s.seconds)}.`),
      el('div', { class: 'table-wrap', tabindex: '0', role: 'region', 'aria-label': 'sweep table (scrolls sideways)' },
        el('table', { class: 'study', id: 'sweep-table' },
          el('thead', {}, el('tr', {}, [...pointers, ...figures.map(([, label]) => label), 'run'].map((h) => el('th', { scope: 'col' }, h)))),
          el('tbody', {}, rows))),
      el('div', { class: 'toolbar' },
        el('label', {}, 'Plot ', quantity),
        el('label', {}, ' against ', against)),
      el('div', { class: 'report-wrap', tabindex: '0', role: 'region', 'aria-label': 'sweep plot' }, img),
    );
    draw();
    this.root.dataset.state = 'ready';
  }

  close() {
    this.job = null;
    this.root.replaceChildren();
    delete this.root.dataset.state;
  }
}
