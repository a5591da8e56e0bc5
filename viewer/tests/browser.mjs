// Browser test of the web viewer: starts `hgs view` on a scene + hybrid model, drives Debian's Chromium
// headless through playwright-core, and checks that the splat canvas is not blank (pixel statistics of a
// screenshot), that a text query lists the named object first and highlights it in 3D (the tinted render
// differs from the plain one, towards orange), that isolate shows fewer splat pixels, that the 2D panel
// images load and that the download link serves a PLY. Screenshots are saved to --out.
// Usage: node browser.mjs --hgs BIN --scene DIR --model PLY --out DIR --query "red mug"
import { spawn } from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';
import { chromium } from 'playwright-core';

const args = Object.fromEntries(process.argv.slice(2).reduce((acc, a, i, all) => {
  if (a.startsWith('--')) acc.push([a.slice(2), all[i + 1]]);
  return acc;
}, []));
for (const k of ['hgs', 'scene', 'model', 'out', 'query'])
  if (!args[k]) { console.error(`browser.mjs: missing --${k}`); process.exit(2); }

let failures = 0;
function check(ok, what) {
  console.log(`${ok ? 'ok  ' : 'FAIL'} ${what}`);
  if (!ok) failures++;
}

function startServer() {
  return new Promise((resolve, reject) => {
    const p = spawn(args.hgs, ['view', args.scene, args.model, '--port', '0', '--threads', '1'],
      { stdio: ['ignore', 'pipe', 'pipe'] });
    let out = '';
    const timer = setTimeout(() => reject(new Error(`hgs view did not start: ${out}`)), 60000);
    p.stdout.on('data', (d) => {
      out += d;
      const m = out.match(/serving at (http:\/\/127\.0\.0\.1:\d+\/)/);
      if (m) { clearTimeout(timer); resolve({ proc: p, url: m[1] }); }
    });
    p.stderr.on('data', (d) => process.stderr.write(d));
    p.on('exit', (c) => { clearTimeout(timer); reject(new Error(`hgs view exited with ${c}: ${out}`)); });
  });
}

// Pixel statistics of a PNG screenshot, decoded by the page itself (no image library needed).
async function pixelStats(page, png, before = null) {
  return page.evaluate(async ({ a, b }) => {
    const load = async (b64) => {
      const img = new Image();
      img.src = `data:image/png;base64,${b64}`;
      await img.decode();
      const c = document.createElement('canvas');
      c.width = img.width; c.height = img.height;
      const g = c.getContext('2d');
      g.drawImage(img, 0, 0);
      return g.getImageData(0, 0, c.width, c.height).data;
    };
    const pa = await load(a);
    const pb = b ? await load(b) : null;
    let n = 0, lit = 0, sum = 0, sum2 = 0, changed = 0, dOrange = 0;
    for (let i = 0; i < pa.length; i += 4) {
      const l = (pa[i] + pa[i + 1] + pa[i + 2]) / 3;
      n++; sum += l; sum2 += l * l;
      if (l > 20) lit++;
      if (pb) {
        const d = Math.abs(pa[i] - pb[i]) + Math.abs(pa[i + 1] - pb[i + 1]) + Math.abs(pa[i + 2] - pb[i + 2]);
        if (d > 30) { changed++; dOrange += ((pa[i] - pa[i + 2]) - (pb[i] - pb[i + 2])) / 255; }
      }
    }
    const mean = sum / n;
    return { pixels: n, lit: lit / n, mean, std: Math.sqrt(Math.max(0, sum2 / n - mean * mean)),
      changed: changed / n, orangeShift: changed ? dOrange / changed : 0 };
  }, { a: png.toString('base64'), b: before ? before.toString('base64') : null });
}

async function settle(page) {
  await page.waitForFunction(() => document.body.dataset.state === 'ready', null, { timeout: 60000 });
  await page.waitForTimeout(1500);  // let the sorter and a few frames run
}

const { proc, url } = await startServer();
console.log(`server: ${url}`);
const browser = await chromium.launch({
  executablePath: '/usr/bin/chromium',
  headless: true,
  args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
    '--disable-component-update', '--no-first-run'],
});
try {
  const page = await browser.newPage({ viewport: { width: 1100, height: 700 } });
  const errors = [];
  page.on('pageerror', (e) => errors.push(String(e)));
  page.on('console', (m) => {
    if (m.type() === 'error') errors.push(m.text());
    if (process.env.HGS_BROWSER_VERBOSE) console.log(`console.${m.type()}: ${m.text()}`);
  });
  await page.goto(url);
  await settle(page);
  const stage = page.locator('#stage');
  const shot0 = await stage.screenshot({ path: path.join(args.out, '1-scene.png') });
  const s0 = await pixelStats(page, shot0);
  console.log('scene render:', JSON.stringify(s0));
  check(s0.lit > 0.05 && s0.std > 8, `canvas is not blank (lit ${(100 * s0.lit).toFixed(1)}%, std ${s0.std.toFixed(1)})`);

  // Query: the named object is listed first and chosen, and becomes the selection.
  await page.fill('#query', args.query);
  await page.press('#query', 'Enter');
  await page.waitForFunction(() => document.body.dataset.selected !== '' && document.body.dataset.selected !== undefined
    && document.body.dataset.state === 'ready', null, { timeout: 60000 });
  await settle(page);
  const first = (await page.locator('#results li').first().textContent()) ?? '';
  const selected = (await page.locator('#results li.selected').textContent()) ?? '';
  check(first.includes(args.query), `first result is "${args.query}" (got "${first.trim()}")`);
  check(selected.includes(args.query), `selected result is "${args.query}" (got "${selected.trim()}")`);
  await page.screenshot({ path: path.join(args.out, '2-query-page.png') });
  const shot1 = await stage.screenshot({ path: path.join(args.out, '3-highlight.png') });
  const s1 = await pixelStats(page, shot1, shot0);
  console.log('highlight render:', JSON.stringify(s1));
  check(s1.changed > 0.002 && s1.orangeShift > 0.05,
    `object highlighted in 3D (changed ${(100 * s1.changed).toFixed(2)}% of pixels, toward orange by ${s1.orangeShift.toFixed(3)})`);

  // 2D panel: overlay and heatmap images of the nearest training view loaded.
  const panel = await page.evaluate(() => ['img-overlay', 'img-heatmap'].map((id) => {
    const im = document.getElementById(id);
    return { src: im.getAttribute('src'), w: im.naturalWidth, ok: im.complete };
  }));
  check(panel.every((p) => p.src && p.w > 0), `2D panel images loaded (${JSON.stringify(panel)})`);

  // Download link serves the object's PLY.
  const href = await page.getAttribute('#dl-object', 'href');
  const head = await page.evaluate(async (h) => (await (await fetch(h)).text()).slice(0, 3), href);
  check(head === 'ply', `download link ${href} serves a PLY`);

  // Isolate: only the object's splats remain, so fewer pixels are lit.
  await page.click('#btn-isolate');
  await page.waitForFunction(() => document.body.dataset.show === 'isolate' && document.body.dataset.state === 'ready',
    null, { timeout: 60000 });
  await settle(page);
  const shot2 = await stage.screenshot({ path: path.join(args.out, '4-isolate.png') });
  const s2 = await pixelStats(page, shot2);
  console.log('isolate render:', JSON.stringify(s2));
  check(s2.lit > 0.001 && s2.lit < 0.8 * s0.lit, `isolate shows only the object (lit ${(100 * s2.lit).toFixed(1)}% vs ${(100 * s0.lit).toFixed(1)}%)`);

  // Clicking another result selects it.
  const other = page.locator('#results li:not(.selected)').first();
  const otherId = await other.getAttribute('data-id');
  await other.click();
  await page.waitForFunction((id) => document.body.dataset.selected === id && document.body.dataset.state === 'ready',
    otherId, { timeout: 60000 });
  check((await page.locator('#results li.selected').getAttribute('data-id')) === otherId, `click selects object ${otherId}`);

  // Jump to another training camera moves the view.
  await page.selectOption('#cameras', '5');
  await page.waitForTimeout(1500);
  await page.screenshot({ path: path.join(args.out, '5-camera-5.png') });
  check(errors.length === 0, `no page errors (${errors.join(' | ').slice(0, 300)})`);
} catch (e) {
  failures++;
  console.log(`FAIL ${e.message.split('\n')[0]}`);
  try {
    const pg = browser.contexts()[0]?.pages()[0];
    if (pg) {
      console.log('page state:', JSON.stringify(await pg.evaluate(() => ({ ...document.body.dataset,
        status: document.getElementById('status').textContent }))));
      await pg.screenshot({ path: path.join(args.out, 'failure.png') });
    }
  } catch (e2) { /* page gone */ }
} finally {
  await browser.close();
  proc.kill('SIGTERM');
}
console.log(failures ? `${failures} check(s) failed` : 'all browser checks passed');
process.exit(failures ? 1 : 0);
