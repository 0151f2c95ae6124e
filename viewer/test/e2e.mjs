// End-to-end test of `scode view` and the viewer page in headless Chromium.
//
// For each model: encode it with the scode binary (at test time, so format changes never leave
// a stale file here), serve it with `scode view --port 0 --no-open`, open the printed URL in
// Debian's Chromium (driven by playwright-core), and check that the page decodes the file in
// WebAssembly, draws triangles with sharp-edge lines, and that zooming in raises the
// subdivision levels chosen from screen size. Saves a screenshot per model and zoom. Then times
// decode + refinement to at least 1 million triangles (+ extraction of the WebGL arrays) in the
// page, and prints it with the gzipped size of the WebAssembly module. Timings are printed,
// not asserted: they depend on the machine and its load.
//
// Usage: node viewer/test/e2e.mjs [--docs]
//   SCODE_BIN   scode binary (default: target/release/scode, else target/debug/scode)
//   CHROMIUM    browser (default /usr/bin/chromium)
//   --docs      write the screenshots to docs/viewer-<model>-<zoom>.png (else target/e2e/)

import { spawn, execFileSync } from 'node:child_process';
import { existsSync, mkdirSync, readFileSync, mkdtempSync, rmSync } from 'node:fs';
import { cpus, loadavg, tmpdir } from 'node:os';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const ROOT = resolve(dirname(fileURLToPath(import.meta.url)), '../..');
const DOCS = process.argv.includes('--docs');
const SHOTS = DOCS ? join(ROOT, 'docs') : join(ROOT, 'target', 'e2e');
const BIN = process.env.SCODE_BIN ||
  [join(ROOT, 'target/release/scode'), join(ROOT, 'target/debug/scode')].find(existsSync);
const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';

function corpusDir() {
  for (const d of [join(ROOT, '../shared/corpus'), '/work/shared/corpus']) if (existsSync(d)) return d;
  return null;
}

function fail(msg) {
  console.error(`e2e: FAIL: ${msg}`);
  process.exitCode = 1;
  throw new Error(msg);
}

// Models: the bundled example always; corpus models when the corpus is there.
const corpus = corpusDir();
// view: camera yaw/pitch (radians) for the screenshots; near: zoom factor of the second shot.
const models = [{ name: 'boss_plate', input: join(ROOT, 'corpus/boss_plate.obj'), args: [], view: [0.7, 0.6], near: 0.45 }];
if (corpus) {
  models.push({ name: 'fandisk', input: join(corpus, 'meshes/fandisk.obj'), args: ['--tolerance', '0.004', '--relative'], view: [3.6, 0.5], near: 0.45, wire: true });
  models.push({ name: 'four_cone', input: join(corpus, 'tess/four_cone_fine.obj'), args: [], view: [0.7, 0.6], near: 0.6 });
} else {
  console.log('e2e: ../shared/corpus not found; testing the bundled boss plate only');
}

function startServer(file) {
  return new Promise((resolveUrl, reject) => {
    const proc = spawn(BIN, ['view', file, '--port', '0', '--no-open'], { stdio: ['ignore', 'pipe', 'inherit'] });
    let out = '';
    proc.stdout.on('data', (d) => {
      out += d;
      const m = out.match(/(http:\/\/127\.0\.0\.1:\d+\/\S*)/);
      if (m) resolveUrl({ proc, url: m[1] });
    });
    proc.on('exit', (code) => reject(new Error(`scode view exited (${code}) before printing a URL: ${out}`)));
  });
}

async function main() {
  if (!BIN) fail('no scode binary: build it (cargo build --release) or set SCODE_BIN');
  if (!existsSync(CHROMIUM)) fail(`${CHROMIUM} not found: apt-get install -y chromium`);
  mkdirSync(SHOTS, { recursive: true });
  const wasmPath = join(ROOT, 'viewer/pkg/scode_wasm_bg.wasm');
  const wasm = readFileSync(wasmPath);
  // The same measure as viewer/build.sh (`gzip -9 -n`): compressors differ by hundreds of
  // bytes on this module, and one of them has to define the budget.
  const gz = execFileSync('gzip', ['-9', '-n', '-c', wasmPath], { maxBuffer: 1 << 24 }).length;
  console.log(`e2e: wasm module ${wasm.length} bytes raw, ${gz} bytes gzipped by gzip -9 (limit 110000)`);
  if (gz > 110000) fail('the gzipped wasm module exceeds 110,000 bytes');

  const work = mkdtempSync(join(tmpdir(), 'scode-e2e-'));
  const browser = await chromium.launch({
    executablePath: CHROMIUM,
    headless: true,
    args: ['--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
      '--disable-quic', '--no-first-run', '--disable-background-networking',
      '--disable-component-update', '--disable-sync'],
  });
  const servers = [];
  try {
    let bench = null;
    for (const model of models) {
      if (!existsSync(model.input)) { console.log(`e2e: ${model.input} missing, skipped`); continue; }
      const file = join(work, `${model.name}.scode`);
      execFileSync(BIN, ['encode', ...model.args, model.input, file], { stdio: ['ignore', 'ignore', 'inherit'] });
      const { proc, url } = await startServer(file);
      servers.push(proc);
      const page = await browser.newPage({ viewport: { width: 1200, height: 760 } });
      const errors = [];
      page.on('pageerror', (e) => errors.push(String(e)));
      page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
      await page.goto(url);
      await page.evaluate(() => window.scodeViewer.ready);
      const far = await page.evaluate(([yaw, pitch]) => {
        window.scodeViewer.setView(yaw, pitch);
        return window.scodeViewer.renderNow();
      }, model.view);
      if (far.error || errors.length) fail(`${model.name}: page error: ${far.error} ${errors.join('; ')}`);
      if (!(far.triangles > 0)) fail(`${model.name}: no triangles drawn`);
      if (!(far.sharpSegments > 0)) fail(`${model.name}: no sharp edges drawn`);
      await page.screenshot({ path: join(SHOTS, `viewer-${model.name}-far.png`) });
      const near = await page.evaluate((f) => { window.scodeViewer.zoom(f); return window.scodeViewer.renderNow(); }, model.near);
      await page.screenshot({ path: join(SHOTS, `viewer-${model.name}-near.png`) });
      if (model.wire) {
        // The same view with the triangles drawn: levels change across the screen, no cracks.
        // (24 px per edge, so the triangles are big enough to see.)
        await page.check('#wire');
        await page.evaluate(() => { window.scodeViewer.state.target = 24; return window.scodeViewer.renderNow(); });
        await page.screenshot({ path: join(SHOTS, `viewer-${model.name}-near-wire.png`) });
        await page.uncheck('#wire');
        await page.evaluate(() => { window.scodeViewer.state.target = 8; });
      }
      console.log(`e2e: ${model.name}: finest level ${far.maxLevel}; full view ${far.triangles} triangles ` +
        `(levels ${far.levels.min}-${far.levels.max}, mean ${far.levels.mean.toFixed(2)}); zoomed in ` +
        `${near.triangles} triangles (levels ${near.levels.min}-${near.levels.max}, mean ${near.levels.mean.toFixed(2)}); ` +
        `decode ${far.timings.decodeMs.toFixed(1)} ms, refine ${far.timings.refineMs.toFixed(1)} ms, ` +
        `extract ${near.timings.extractMs.toFixed(1)} ms`);
      if (!(near.levels.mean > far.levels.mean)) fail(`${model.name}: zooming in did not raise the level`);
      if (errors.length) fail(`${model.name}: page errors: ${errors.join('; ')}`);
      if (model.name === 'fandisk' || (!bench && model === models[models.length - 1])) {
        // Decode + refine to about 1M triangles (the uniform level nearest it) + WebGL arrays;
        // first run cold, then best of 3.
        // Wall time from the page, CPU time of the page's main thread from the DevTools
        // protocol (ThreadTime), which stays meaningful when other work loads the machine.
        const cdp = await page.context().newCDPSession(page);
        await cdp.send('Performance.enable');
        const threadTime = async () =>
          (await cdp.send('Performance.getMetrics')).metrics.find((x) => x.name === 'ThreadTime')?.value ?? NaN;
        await page.evaluate(async (fileUrl) => {
          window.benchBytes = new Uint8Array(await (await fetch(fileUrl)).arrayBuffer());
        }, new URL(url).searchParams.get('file'));
        bench = { runs: [] };
        for (let i = 0; i < 4; i++) {
          const before = await threadTime();
          const r = await page.evaluate(() => window.scodeViewer.benchmark(window.benchBytes, 1e6));
          r.cpuMs = (await threadTime() - before) * 1000;
          bench.runs.push(r);
        }
        bench.model = model.name;
      }
      await page.close();
    }
    if (bench) {
      const [cold, ...warm] = bench.runs;
      const best = warm.reduce((a, b) => (a.totalMs < b.totalMs ? a : b));
      const line = (r) => `decode ${r.decodeMs.toFixed(1)} + refine ${r.refineMs.toFixed(1)} + ` +
        `arrays ${r.extractMs.toFixed(1)} = ${r.totalMs.toFixed(1)} ms wall, ${r.cpuMs.toFixed(1)} ms main-thread CPU`;
      console.log(`e2e: 1M benchmark, ${bench.model} level ${cold.level}: ${cold.triangles} triangles, ` +
        `${cold.vertices} vertices`);
      console.log(`e2e:   first run ${line(cold)}`);
      console.log(`e2e:   best of ${warm.length} ${line(best)}`);
      console.log(`e2e:   (load average ${loadavg().map((x) => x.toFixed(1)).join(' ')} on ${cpus().length} cores)`);
    }
  } finally {
    await browser.close();
    for (const p of servers) p.kill();
    rmSync(work, { recursive: true, force: true });
  }
  console.log(`e2e: screenshots in ${SHOTS}`);
  console.log('e2e: ok');
}

main().catch((e) => {
  if (!process.exitCode) console.error(e);
  process.exitCode = 1;
});
