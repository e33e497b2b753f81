// The result view of a convergence study (job kind "study"): the reference solution, the
// error table with observed orders, the least-squares orders, and the server's report SVG
// (error vs h or k with slope guides; error vs time). Nothing is drawn here: the report is
// the server's, embedded as an <img>. Summary contract:
//   {kind: "study", vary: "h"|"k"|"hk", reference: {h, k, w_V, zeta_Z0, seconds},
//    rows: [{h, k, err_w, err_zeta, order_w, order_zeta (null on the first row), unknowns,
//            steps, seconds}], lsq_order_w, lsq_order_zeta}

import * as api from './api.js';
import { el, fmt, fmtStep, fmtSeconds } from './util.js';

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
    const ref = s.reference || {};
    const vary = s.vary || '';
    const order = (x) => (x === null || x === undefined ? '–' : Number(x).toFixed(3));
    const num = (x) => el('td', { class: 'num' }, x);
    const rows = (s.rows || []).map((r) =>
      el('tr', {},
        num(fmtStep(r.h)), num(fmtStep(r.k)),
        num(fmt(r.err_w)), num(order(r.order_w)),
        num(fmt(r.err_zeta)), num(order(r.order_zeta)),
        num(r.unknowns ?? '–'), num(r.steps ?? '–'), num(fmtSeconds(r.seconds))));
    const img = el('img', { class: 'report', alt: 'error against the mesh size or time step, and error over time' });
    this.root.replaceChildren(
      el('div', { class: 'view-head' },
        el('h2', {}, job.scene || 'study', ' ', el('small', {}, id.slice(0, 8))),
        el('nav', { class: 'downloads', 'aria-label': 'downloads' },
          api.keyedLink(el('a', { href: `/jobs/${id}/summary`, download: `study-${id.slice(0, 8)}.json` }, 'summary JSON')),
          api.keyedLink(el('a', { href: report, download: `report-${id.slice(0, 8)}.svg` }, 'report SVG')))),
      el('p', { class: 'run-info' },
        `Convergence in ${vary === 'hk' ? 'h = k' : vary || '?'} against the reference h = ${fmtStep(ref.h)}, k = ${fmtStep(ref.k)} `,
        `(|w|_V = ${fmt(ref.w_V, 10)}, |ζ|_Z0 = ${fmt(ref.zeta_Z0, 10)}, ${fmtSeconds(ref.seconds)}). `,
        `Least-squares orders: w ${order(s.lsq_order_w)}, ζ ${order(s.lsq_order_zeta)}.`),
      el('div', { class: 'table-wrap' },
        el('table', { class: 'study', id: 'study-table' },
          el('thead', {}, el('tr', {},
            ['h', 'k', 'err w', 'order', 'err ζ', 'order', 'unknowns', 'steps', 'time'].map((h) => el('th', {}, h)))),
          el('tbody', {}, rows))),
      img,
    );
    api.keyedImage(img, report);
    this.root.dataset.state = 'ready';
  }

  close() {
    this.job = null;
    this.root.replaceChildren();
    delete this.root.dataset.state;
  }
}
