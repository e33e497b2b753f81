// How long the browser client takes to open a finished job's result, and what it downloads:
//   node tests/browser/open-time.mjs <base-url> <job-id>
// Headless Chromium (Debian's, or $CHROMIUM) with a fresh profile, as the browser tests run
// it (SwiftShader WebGL). Times from navigation to the viewer being ready with its first
// picture drawn (3D: the canvas's first frame), and lists every response of the job's
// routes with its body size. Not a test: the measurement behind the 1/64 figures of
// docs/src/reference/surface.md.

import { chromium } from 'playwright-core';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';

const [base, id] = process.argv.slice(2);
if (!base || !id) {
  console.error('usage: node open-time.mjs <base-url> <job-id>');
  process.exit(2);
}
const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), 'contact-sim-open-time-'));
const context = await chromium.launchPersistentContext(userDataDir, {
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  headless: true,
  viewport: { width: 1280, height: 800 },
  args: ['--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
    '--no-first-run', '--disable-background-networking', '--disable-component-update', '--disable-sync'],
});
const page = await context.newPage();
const responses = [];
page.on('response', async (r) => {
  const url = new URL(r.url());
  if (!url.pathname.startsWith(`/jobs/${id}`)) return;
  const at = Date.now() - t0;
  const bytes = await r.request().sizes().then((z) => z.responseBodySize, () => -1);
  responses.push({ path: url.pathname.slice(`/jobs/${id}`.length) + url.search, status: r.status(), bytes, at_ms: at, done_ms: Date.now() - t0 });
});
page.on('pageerror', (e) => console.error(`page error: ${e}`));
const t0 = Date.now();
await page.goto(`${base}/#job=${id}`);
await page.waitForSelector(`#viewer[data-state="ready"][data-job="${id}"]`, { timeout: 120_000 });
const ready = Date.now() - t0;
const three = await page.locator('#mesh-canvas-3d').count();
if (three) await page.waitForFunction(() => Number(document.querySelector('#mesh-canvas-3d')?.dataset.frame || 0) > 0, null, { timeout: 120_000 });
const drawn = Date.now() - t0;
const info = await page.textContent('.run-info').catch(() => '');
// Let late responses finish their size count.
await page.waitForTimeout(500);
const total = responses.reduce((s, r) => s + Math.max(r.bytes, 0), 0);
console.log(JSON.stringify({ ready_s: ready / 1000, first_picture_s: drawn / 1000, view: three ? '3d' : '2d', bytes: total, info, responses }, null, 1));
await context.close();
fs.rmSync(userDataDir, { recursive: true, force: true });
