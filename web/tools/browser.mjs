// Drives Debian's Chromium headless (playwright-core, no browser download) to the web viewer:
// waits until the viewer shows its current cell, then takes a screenshot of the canvas
// (`--screenshot OUT.png`) and/or measures the viewer's frame rate with the page's own frame
// timer over `--bench SECONDS` (the viewer's `walk=1` mode walks the cells). Prints one JSON
// object. Exit codes: 0 done, 1 the viewer failed (its error is printed), 3 the browser could not
// start (tests skip on it, with the reason).
//
// usage: node browser.mjs URL [--screenshot OUT.png|.jpg [--delay SECONDS]] [--bench SECONDS [--warmup SECONDS]] [--size 960x540]
// Software WebGL: SwiftShader through ANGLE. LEMI_CHROMIUM overrides /usr/bin/chromium.
import { chromium } from 'playwright-core';

const args = process.argv.slice(2);
const url = args[0];
const opt = (name, dflt) => {
  const i = args.indexOf(name);
  return i >= 0 ? args[i + 1] : dflt;
};
if (!url) {
  console.error('usage: node browser.mjs URL [--screenshot OUT.png] [--bench SECONDS] [--size WxH]');
  process.exit(2);
}
const [width, height] = opt('--size', '960x540').split('x').map(Number);
const shot = opt('--screenshot', null);
const bench = Number(opt('--bench', '0'));
const warmup = Number(opt('--warmup', '0'));
const timeout = Number(opt('--timeout', '180')) * 1000;

let browser;
try {
  browser = await chromium.launch({
    executablePath: process.env.LEMI_CHROMIUM || '/usr/bin/chromium',
    headless: true,
    args: [
      '--no-sandbox',
      '--disable-background-networking',
      '--disable-component-update',
      '--use-angle=swiftshader',
      '--enable-unsafe-swiftshader',
      '--ignore-gpu-blocklist',
    ],
  });
} catch (e) {
  console.log(JSON.stringify({ ok: false, browser: false, error: `cannot start the browser: ${e.message.split('\n')[0]}` }));
  process.exit(3);
}
const out = { ok: false, url, width, height };
try {
  const page = await browser.newPage({ viewport: { width, height }, deviceScaleFactor: 1 });
  const logs = [];
  page.on('console', (m) => logs.push(`${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => logs.push(`pageerror: ${e.message}`));
  await page.goto(url, { timeout });
  await page.waitForFunction(() => window.lemi && (window.lemi.ready || window.lemi.error), null, { timeout, polling: 100 });
  const state = await page.evaluate(() => ({
    error: window.lemi.error, renderer: window.lemi.renderer, cell: window.lemi.shownCell,
    texture_formats: window.lemi.textureFormats,
    fetched_bytes: window.lemi.fetchedBytes, transferred_bytes: window.lemi.transferredBytes,
  }));
  Object.assign(out, state);
  if (state.error) throw new Error(`the viewer failed: ${state.error}`);
  if (shot) {
    await page.waitForTimeout(Number(opt('--delay', '0')) * 1000);
    await page.screenshot({ path: shot, omitBackground: true, clip: { x: 0, y: 0, width, height }, timeout });
    out.screenshot = shot;
  }
  if (bench > 0) {
    // let the streaming settle (every predicted cell fetched, parsed and uploaded) first
    await page.waitForTimeout(warmup * 1000);
    const start = await page.evaluate(() => window.lemi.frameTimes.length);
    await page.waitForTimeout(bench * 1000);
    const r = await page.evaluate((s) => ({
      times: window.lemi.frameTimes.slice(s),
      cells: window.lemi.loadedCells,
      stalls: window.lemi.stalls,
      fetched: window.lemi.fetchedBytes,
      transferred: window.lemi.transferredBytes,
    }), start);
    const t = r.times.slice().sort((a, b) => a - b);
    const sum = r.times.reduce((a, b) => a + b, 0);
    out.bench = {
      seconds: bench,
      warmup_seconds: warmup,
      frames: t.length,
      fps_mean: t.length ? (1000 * t.length) / sum : 0,
      frame_ms_median: t.length ? t[Math.floor(t.length / 2)] : null,
      frame_ms_p95: t.length ? t[Math.min(t.length - 1, Math.floor(0.95 * t.length))] : null,
      frame_ms_max: t.length ? t[t.length - 1] : null,
      loaded_cells: r.cells.length,
      stalled_frames: r.stalls,
      fetched_bytes: r.fetched,
      transferred_bytes: r.transferred,
    };
  }
  out.ok = true;
  out.logs = logs.slice(0, 50);
} catch (e) {
  out.error = e.message;
  console.log(JSON.stringify(out));
  await browser.close();
  process.exit(1);
}
console.log(JSON.stringify(out));
await browser.close();
