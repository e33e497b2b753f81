// Real-browser tests of the contact-sim client, driven by playwright-core in Debian's
// Chromium. Run by tests/browser.rs against a server it started:
//
//   node tests/browser/client.mjs <base-url> <screenshot-dir>
//
// Exit code 0 when every check passed. Environment: CHROMIUM (default /usr/bin/chromium).
//
// 1. Submit paper-exp2 at h = k = 1/8 through the form, wait (through the UI) until the
//    result is shown, and check from the canvas pixels that the damage colouring is not
//    uniform; move the time slider (Home: the initial state, step 0) and check that the step
//    and the picture change; play back to the end; screenshots at 1280×800 and on a narrow
//    screen.
// 2. Submit a scene with mesh.h = -1 from the editor and check that the server's message is
//    shown on the editor line of that key and in the error list; then a preset with
//    overrides.h = -1 and check the message under the h input.
// 3. A long job: its progress moves in the list (SSE), Cancel stops it, Delete removes it.
// 4. The study view of a real study job.

import { chromium } from 'playwright-core';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';

const [base, outDir] = process.argv.slice(2);
if (!base || !outDir) {
  console.error('usage: node client.mjs <base-url> <screenshot-dir>');
  process.exit(2);
}
fs.mkdirSync(outDir, { recursive: true });
const executablePath = process.env.CHROMIUM || '/usr/bin/chromium';

// Never hang CI: the whole run must finish in this time.
const overall = setTimeout(() => {
  console.error('FAIL: browser tests took longer than 240 s');
  process.exit(1);
}, 240_000);

function check(cond, what) {
  if (!cond) throw new Error(`check failed: ${what}`);
  console.log(`  ok: ${what}`);
}

// Chromium as this machine needs it: headless, no sandbox (root), no GPU, and no background
// connections (the network is closed; they would fail at every start).
const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), 'contact-sim-chromium-'));
const context = await chromium.launchPersistentContext(userDataDir, {
  executablePath,
  headless: true,
  viewport: { width: 1280, height: 800 },
  args: [
    '--no-sandbox',
    '--disable-gpu',
    '--disable-quic',
    '--no-first-run',
    '--disable-background-networking',
    '--disable-component-update',
    '--disable-sync',
  ],
});

const pageErrors = [];
async function openPage(setup, hash = '') {
  const page = await context.newPage();
  if (setup) await setup(page);
  page.on('pageerror', (e) => pageErrors.push(String(e)));
  page.on('console', (m) => {
    // A 422 answer is logged by the browser as a failed resource; that one is expected.
    if (m.type() === 'error' && !/status of 422/.test(m.text())) console.log(`  [console.${m.type()}] ${m.text()}`);
  });
  await page.goto(base + '/' + hash);
  await page.waitForSelector('body[data-ready="true"]', { timeout: 15_000 });
  return page;
}

/**
 * Pixel statistics of the mesh canvas, computed in the page from getImageData. A pixel
 * counts as "field" when its colour is exactly one of the colour map's 256 entries (the
 * renderer writes those with putImageData; lines drawn on top have other colours).
 */
function canvasStats(page) {
  return page.evaluate(async () => {
    const { LUT } = await import('/client/colormap.js');
    const index = new Map();
    for (let i = 0; i < 256; i++) index.set((LUT[3 * i] << 16) | (LUT[3 * i + 1] << 8) | LUT[3 * i + 2], i);
    const c = document.querySelector('#mesh-canvas');
    const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
    const hist = new Array(256).fill(0);
    let opaque = 0, field = 0, hash = 2166136261;
    for (let o = 0; o < d.length; o += 4) {
      hash = Math.imul(hash ^ (d[o] | (d[o + 1] << 8) | (d[o + 2] << 16) | (d[o + 3] << 24)), 16777619) >>> 0;
      if (d[o + 3] !== 255) continue;
      opaque++;
      const k = index.get((d[o] << 16) | (d[o + 1] << 8) | d[o + 2]);
      if (k !== undefined) {
        hist[k]++;
        field++;
      }
    }
    let lo = 255, hi = 0, mean = 0;
    hist.forEach((n, k) => {
      if (n) { lo = Math.min(lo, k); hi = Math.max(hi, k); mean += n * k; }
    });
    mean /= field || 1;
    let v = 0;
    hist.forEach((n, k) => (v += n * (k - mean) ** 2));
    return {
      width: c.width, height: c.height, pixels: c.width * c.height, opaque, field,
      distinct: hist.filter((n) => n > 0).length, indexMin: lo, indexMax: hi,
      indexStd: Math.sqrt(v / (field || 1)), hash,
    };
  });
}

async function testSimulation() {
  console.log('test 1: paper-exp2 at h = k = 1/8, damage colouring, slider, play');
  const page = await openPage();
  await page.selectOption('#preset-select', 'paper-exp2');
  await page.fill('#ov-h', '1/8');
  await page.fill('#ov-k', '1/8');
  await page.click('#submit-preset');
  // Completion as the user sees it: the job turns "succeeded" and its results appear.
  await page.waitForSelector('#job-list li.job[data-status="succeeded"]', { timeout: 90_000 });
  await page.waitForSelector('#viewer[data-state="ready"]', { timeout: 30_000 });
  const jobId = await page.getAttribute('#viewer', 'data-job');
  check(/^[0-9a-f-]{36}$/.test(jobId || ''), `result view shows job ${jobId}`);
  check((await page.inputValue('#quantity')) === 'zeta', 'coloured by damage ζ by default');
  const lastStep = await page.getAttribute('#viewer', 'data-step');
  check(lastStep === '8', `shows the last stored step (step ${lastStep})`);
  check((await page.textContent('#step-label')).includes('step 8'), 'step label names step 8');
  const cb = await page.textContent('#colorbar');
  check(/damage ζ: min [\d.]+, max [\d.]+/.test(cb) && !cb.includes('uniform'), `colour bar with range: "${cb.trim()}"`);

  const s8 = await canvasStats(page);
  console.log('  canvas at step 8:', JSON.stringify(s8));
  // Thresholds from the colour map (256 entries): the body covers a good part of the canvas,
  // and a non-uniform ζ spread over the auto range uses many entries across the map, while a
  // uniform field would be a single entry (index 127/128).
  check(s8.field > 0.15 * s8.pixels, `field pixels cover ${(100 * s8.field / s8.pixels).toFixed(1)}% of the canvas (> 15%)`);
  check(s8.distinct >= 64, `${s8.distinct} distinct colour-map entries (>= 64 of 256)`);
  check(s8.indexMax - s8.indexMin >= 192, `entries span ${s8.indexMin}..${s8.indexMax} (>= 3/4 of the map)`);
  check(s8.indexStd >= 20, `standard deviation of the entry index ${s8.indexStd.toFixed(1)} (>= 20)`);

  const plots = await page.locator('#plots svg.plot path').count();
  check(plots === 4, `${plots} norm plots drawn`);
  const vtu = await page.getAttribute('#dl-vtu', 'href');
  check(vtu === `/jobs/${jobId}/fields/8.vtu`, `VTU link of the shown step: ${vtu}`);
  for (const href of await page.locator('.downloads a').evaluateAll((as) => as.map((a) => a.getAttribute('href')))) {
    const r = await page.request.get(base + href);
    check(r.status() === 200, `download ${href} answers 200`);
  }
  await page.screenshot({ path: path.join(outDir, 'client-exp2-step8.png'), fullPage: true });

  // The slider: Home goes to the first step of the PVD, the initial state (step 0, t = 0,
  // ζ0 = 1 everywhere: one colour).
  await page.focus('#step-slider');
  await page.keyboard.press('Home');
  await page.waitForSelector('#viewer[data-step="0"]', { timeout: 10_000 });
  const label0 = await page.textContent('#step-label');
  check(label0.includes('step 0 ') && label0.includes('t = 0'), `step label names the initial state: "${label0}"`);
  check((await page.textContent('#colorbar')).includes('(uniform)'), 'ζ0 = 1 is uniform at t = 0');
  const s0 = await canvasStats(page);
  console.log('  canvas at step 0:', JSON.stringify(s0));
  check(s0.distinct === 1, `uniform ζ at step 0 is drawn with ${s0.distinct} colour-map entry`);
  check(s0.hash !== s8.hash, 'the canvas changed with the step');
  await page.keyboard.press('ArrowRight');
  await page.waitForSelector('#viewer[data-step="1"]', { timeout: 10_000 });
  check((await page.textContent('#step-label')).includes('step 1 '), 'step label names step 1 after ArrowRight');
  const s1 = await canvasStats(page);
  console.log('  canvas at step 1:', JSON.stringify(s1));
  check(s1.hash !== s8.hash, 'the canvas changed with the step');
  // Consistency of the statistic: a step whose ζ is uniform (the colour bar says so) is
  // drawn in a single colour-map entry.
  if ((await page.textContent('#colorbar')).includes('(uniform)')) {
    check(s1.distinct === 1, `uniform ζ at step 1 is drawn with ${s1.distinct} colour-map entry`);
  }
  await page.keyboard.press('ArrowRight');
  await page.waitForSelector('#viewer[data-step="2"]', { timeout: 10_000 });
  const s2 = await canvasStats(page);
  console.log('  canvas at step 2:', JSON.stringify(s2));
  check(s2.hash !== s1.hash, 'ArrowRight shows step 2, another picture');
  await page.screenshot({ path: path.join(outDir, 'client-exp2-step2.png'), fullPage: true });

  // Play runs to the last step and stops; the same step draws the same picture.
  await page.click('#play');
  await page.waitForSelector('#viewer[data-step="8"]', { timeout: 20_000 });
  await page.waitForFunction(() => document.querySelector('#play').textContent.includes('Play'), null, { timeout: 10_000 });
  const again = await canvasStats(page);
  check(again.hash === s8.hash, 'play ends at step 8 with the same picture as before');

  // Other colourings.
  for (const q of ['von_mises', 'w']) {
    await page.selectOption('#quantity', q);
    const s = await canvasStats(page);
    check(s.distinct >= 16 && s.hash !== s8.hash, `coloured by ${q}: ${s.distinct} entries`);
  }
  await page.selectOption('#quantity', 'zeta');

  // Narrow screen: one column, nothing wider than the window.
  await page.setViewportSize({ width: 390, height: 844 });
  await page.waitForTimeout(300);
  const overflow = await page.evaluate(() => document.documentElement.scrollWidth - window.innerWidth);
  check(overflow <= 0, `no horizontal scrolling at 390 px (overflow ${overflow} px)`);
  const narrow = await canvasStats(page);
  check(narrow.distinct >= 64, `canvas redrawn at the narrow width (${narrow.width}×${narrow.height} px, ${narrow.distinct} entries)`);
  await page.screenshot({ path: path.join(outDir, 'client-exp2-narrow.png'), fullPage: true });
  await page.close();
  return { step8: s8, step0: s0, step1: s1, step2: s2 };
}

async function testInvalidScene() {
  console.log('test 2: invalid scene, errors next to the offending field');
  const page = await openPage();
  await page.selectOption('#preset-select', 'paper-exp2');
  await page.click('#edit-preset');
  await page.waitForFunction(() => document.querySelector('#scene-text').value.includes('paper-exp2'));
  const doc = JSON.parse(await page.inputValue('#scene-text'));
  doc.mesh.h = -1;
  const text = JSON.stringify(doc, null, 2);
  await page.fill('#scene-text', text);

  // What the server says about this scene (the UI must show exactly this message).
  const expected = await page.evaluate(async (body) => {
    const r = await fetch('/jobs', { method: 'POST', headers: { 'Content-Type': 'application/json' }, body });
    return { status: r.status, body: await r.json() };
  }, text);
  check(expected.status === 422, `the server refuses mesh.h = -1 with 422`);
  const err = expected.body.errors.find((e) => e.pointer === '/mesh/h');
  check(!!err, `the 422 names /mesh/h: "${err?.message}"`);

  await page.click('#submit-scene');
  const note = page.locator('.editor-notes .note[data-pointer~="/mesh/h"]');
  await note.waitFor({ timeout: 10_000 });
  const noteText = await note.textContent();
  check(noteText.includes(err.message), `editor note contains the message: "${noteText}"`);
  const line = Number(await note.getAttribute('data-line'));
  const lineText = text.split('\n')[line];
  check(/"h": -1/.test(lineText), `the note is on line ${line + 1}, the line of the key: ${lineText.trim()}`);
  const bad = await page.locator('.editor-backdrop .line.bad').evaluateAll((ls, l) => ls.map((x) => [...x.parentNode.children].indexOf(x)), line);
  check(bad.includes(line), `line ${line + 1} is highlighted`);
  // Visually next to it: the note's box is on the same row as the line in the textarea.
  const ta = await page.locator('#scene-text').boundingBox();
  const nb = await note.boundingBox();
  const rowTop = ta.y + 6 + line * 20 - (await page.$eval('#scene-text', (t) => t.scrollTop));
  check(nb && Math.abs(nb.y - rowTop) < 3 && nb.x > ta.x, `note drawn on that row (y ${nb?.y.toFixed(0)} vs ${rowTop.toFixed(0)})`);
  check(nb.y >= ta.y && nb.y + nb.height <= ta.y + ta.height, 'the note is inside the visible part of the editor');
  const item = await page.textContent('#scene-errors li[data-pointer="/mesh/h"]');
  check(item.includes('/mesh/h') && item.includes(err.message), `error list entry: "${item}"`);
  await page.screenshot({ path: path.join(outDir, 'client-invalid-scene.png'), fullPage: true });

  // The preset form: overrides.h = -1 is reported under the h input.
  const want = await page.evaluate(async () => {
    const r = await fetch('/jobs', { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify({ preset: 'paper-exp2', overrides: { h: -1 } }) });
    return (await r.json()).errors.find((e) => e.pointer === '/overrides/h')?.message;
  });
  await page.fill('#ov-h', '-1');
  await page.click('#submit-preset');
  const fe = page.locator('.field-error[data-for="/overrides/h"]');
  await page.waitForFunction(() => document.querySelector('.field-error[data-for="/overrides/h"]').textContent !== '');
  check((await fe.textContent()).includes(want), `message under the h input: "${await fe.textContent()}"`);
  check((await page.getAttribute('#ov-h', 'aria-invalid')) === 'true', 'the h input is marked invalid');
  await page.close();
}

async function testLiveJob() {
  console.log('test 3: live progress (SSE), cancel, delete');
  const events = [];
  const page = await openPage((p) => p.on('request', (r) => events.push(r.url())));
  page.on('dialog', (d) => d.accept()); // "Delete job ...?"
  await page.selectOption('#preset-select', 'paper-exp2');
  await page.fill('#ov-h', '1/16');
  await page.fill('#ov-k', '1/20000');
  await page.click('#submit-preset');
  await page.waitForSelector('#viewer[data-state="waiting"]', { timeout: 10_000 });
  const id = await page.getAttribute('#viewer', 'data-job');
  const item = `#job-list li.job[data-id="${id}"]`;
  await page.waitForSelector(`${item}[data-status="running"]`, { timeout: 30_000 });
  const stepOf = () => page.$eval(`${item} .job-detail`, (e) => Number((/^(\d+)\//.exec(e.textContent) || [])[1] || 0));
  const first = await stepOf();
  await page.waitForFunction(
    ([sel, s0]) => Number((/^(\d+)\//.exec(document.querySelector(sel).textContent) || [])[1] || 0) > s0 + 10,
    [`${item} .job-detail`, first],
    { timeout: 30_000 },
  );
  const later = await stepOf();
  check(later > first, `progress moves in the list: step ${first} -> ${later} of 20000`);
  check(events.some((u) => u.endsWith(`/jobs/${id}/events`)), 'progress comes from the SSE stream');
  check((await page.textContent('#viewer')).includes('is running: step'), 'the result pane shows the running state');
  await page.click(`${item} button:has-text("Cancel")`);
  await page.waitForSelector(`${item}[data-status="cancelled"]`, { timeout: 15_000 });
  check(true, 'Cancel stops the job (status cancelled)');
  await page.click(`${item} button:has-text("Delete")`);
  await page.waitForSelector(item, { state: 'detached', timeout: 10_000 });
  const gone = (await page.request.get(`${base}/jobs/${id}`)).status();
  check(gone === 404, 'Delete removes the job (GET /jobs/{id} is 404)');
  await page.close();
}

/**
 * A real convergence study submitted to the server (coarse, a second or two): the view shows
 * the server's table (h as 1/n, "–" for the first row's orders, the least-squares orders) and
 * embeds the server's report SVG; nothing else is drawn.
 */
async function testStudyView() {
  console.log('test 4: study view (a real study job)');
  const request = context.request;
  const submit = await request.post(`${base}/jobs`, {
    data: { study: { scene: 'paper-convergence', h: ['1/2', '1/4', '1/8'], k: '1/16', reference: { h: '1/16', k: '1/16' } } },
  });
  check(submit.status() === 202 || submit.status() === 200, `study accepted (${submit.status()})`);
  const id = (await submit.json()).id;
  const t0 = Date.now();
  let job;
  for (;;) {
    job = await (await request.get(`${base}/jobs/${id}`)).json();
    if (['succeeded', 'failed', 'cancelled'].includes(job.status)) break;
    check(Date.now() - t0 < 60_000, 'the study finishes within 60 s');
    await new Promise((r) => setTimeout(r, 100));
  }
  check(job.status === 'succeeded' && job.kind === 'study', `study ${job.status}`);
  const summary = await (await request.get(`${base}/jobs/${id}/summary`)).json();
  const page = await openPage(async () => {}, `#job=${id}`);
  await page.waitForSelector(`#viewer[data-state="ready"][data-job="${id}"]`, { timeout: 10_000 });
  const rows = await page.$$eval('#study-table tbody tr', (trs) => trs.map((tr) => [...tr.cells].map((c) => c.textContent)));
  check(rows.length === 3, `${rows.length} table rows`);
  const order = Number(summary.rows[1].order_w).toFixed(3);
  check(rows[0][0] === '1/2' && rows[0][3] === '–' && rows[1][3] === order, `rows read h as 1/n and orders (first row: –): ${JSON.stringify(rows[1])}, expected ${order}`);
  const img = await page.$eval('#viewer img.report', (i) => ({ src: i.getAttribute('src'), w: i.naturalWidth }));
  check(img.src === `/jobs/${id}/report.svg` && img.w > 0, `report SVG embedded and loaded (${img.w} px wide)`);
  check((await page.locator('#viewer canvas').count()) === 0, 'nothing else is drawn for a study');
  const lsq = Number(summary.lsq_order_w).toFixed(3);
  check((await page.textContent('#viewer')).includes(lsq), `least-squares order ${lsq} shown`);
  await page.screenshot({ path: path.join(outDir, 'client-study.png'), fullPage: true });
  await page.close();

  // A simulation with an error bar shows the estimate at T next to the run's facts.
  const scene = await (await request.get(`${base}/presets/paper-exp2`)).json();
  scene.mesh.h = '1/8';
  scene.time = { t_end: 1, k: '1/8' };
  scene.error_estimate = true;
  const sim = await request.post(`${base}/jobs`, { data: scene });
  check(sim.status() === 202, `scene with error_estimate accepted (${sim.status()})`);
  const simId = (await sim.json()).id;
  const t1 = Date.now();
  while ((await (await request.get(`${base}/jobs/${simId}`)).json()).status !== 'succeeded') {
    check(Date.now() - t1 < 60_000, 'the simulation finishes within 60 s');
    await new Promise((r) => setTimeout(r, 100));
  }
  const estPage = await openPage(async () => {}, `#job=${simId}`);
  await estPage.waitForSelector(`#viewer[data-state="ready"][data-job="${simId}"]`, { timeout: 15_000 });
  const text = await estPage.textContent('#error-estimate');
  check(/Estimated error at T .*w [0-9.]+ %/.test(text), `error estimate shown: ${text}`);
  await estPage.close();
}

let failed = false;
try {
  await testSimulation();
  await testInvalidScene();
  await testLiveJob();
  await testStudyView();
  if (pageErrors.length) throw new Error(`uncaught errors in the page: ${pageErrors.join('; ')}`);
  console.log(`PASS (screenshots in ${outDir})`);
} catch (e) {
  failed = true;
  console.error(`FAIL: ${e.stack || e}`);
  for (const p of context.pages()) {
    await p.screenshot({ path: path.join(outDir, 'failure.png'), fullPage: true }).catch(() => {});
  }
} finally {
  await context.close().catch(() => {});
  fs.rmSync(userDataDir, { recursive: true, force: true });
  clearTimeout(overall);
}
process.exit(failed ? 1 : 0);
