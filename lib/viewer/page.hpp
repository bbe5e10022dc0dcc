#pragma once
// The page transhuman-view serves: the rendered person in an <img>, the camera dragged with
// three.js's OrbitControls (orbit, zoom, pan around the body's centre; no WebGL is needed),
// progressive requests (while moving: views of the frame's bake at full size, or small and fast
// network views until the bake is ready; full size from the network when the camera rests), the
// bake's progress, a frame slider, a person selector, snaps to the dataset cameras and the
// reference views.

namespace th::viewer {

inline constexpr const char* kPage = R"HTML(<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>TransHuman viewer</title>
<style>
body { font: 14px system-ui, sans-serif; margin: 0; background: #1e2430; color: #dde; }
header, #controls, #refs { padding: 6px 12px; }
#stage { position: relative; width: 512px; height: 512px; margin: 0 12px; background: #000; cursor: grab;
         touch-action: none; user-select: none; }
#stage img { width: 100%; height: 100%; image-rendering: auto; pointer-events: none; }
#row { display: flex; align-items: flex-start; }
#truth img { width: 512px; }
#refs img { height: 96px; margin-right: 6px; border: 1px solid #445; }
button { margin: 2px; }
#status { font-family: monospace; }
</style>
<script src="three/three.min.js"></script>
<script src="three/OrbitControls.js"></script>
</head>
<body>
<header><b>TransHuman viewer</b> &mdash; drag to orbit, wheel to zoom, right-drag to pan</header>
<div id="controls">
  person <select id="human"></select>
  frame <input id="frame" type="range" min="0" max="0" step="1" value="0"> <span id="frame-label"></span>
  show <select id="mode"><option>rgb</option><option>depth</option><option>acc</option></select>
  <div id="snaps">cameras: </div>
</div>
<div id="row"><div id="stage"><img id="view" alt="rendered view"></div>
<div id="truth" hidden><img id="truth-img" alt="ground truth"><div id="score"></div></div></div>
<div id="status">loading</div>
<div id="bake"></div>
<div id="refs">reference views: </div>
<script>
'use strict';
const $ = (id) => document.getElementById(id);
const state = { client: Math.random().toString(36).slice(2), info: null, frame: null, human: 0, frames: [], seq: 0, shown: 0, size: [512, 512], timer: 0, baked: {}, inflight: 0, times: [] };
const frameKey = () => state.human + '/' + state.frames[$('frame').value];
const camera = new THREE.PerspectiveCamera(40, 1, 0.01, 1000);
let controls = null;

async function json(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(url + ': ' + (await r.text()));
  return r.json();
}

// Asks for a view: while moving 'baked' (the frame's bake, the view's size) or, until the bake is
// ready, 'fast' (128 px, 16 samples); when the camera rests 'mid' first on a large view (256 px,
// at most 32 samples), then 'full' (the view's size and samples).
async function request(level) {
  const fast = level === 'fast' || level === 'baked';
  const seq = ++state.seq;
  const [w0, h0] = state.size;
  const key = frameKey();
  const side = { fast: 128, mid: 256, full: Infinity, baked: Infinity }[level];
  const scale = Math.min(1, side / Math.max(w0, h0));
  const w = Math.max(8, Math.round(w0 * scale)), h = Math.max(8, Math.round(h0 * scale));
  const dir = new THREE.Vector3();
  camera.getWorldDirection(dir);
  const v = (p) => [p.x, p.y, p.z].map((x) => x.toFixed(6)).join(',');
  const params = new URLSearchParams({
    human: state.human, frame: state.frames[$('frame').value], eye: v(camera.position), forward: v(dir),
    up: v(camera.up), fovy: camera.fov.toFixed(4), width: w, height: h, mode: $('mode').value, seq,
    client: state.client });
  if (level === 'fast') params.set('samples', 16);
  if (level === 'mid') params.set('samples', Math.min(32, state.info.samples));
  if (level === 'baked') { params.set('baked', 1); params.set('format', 'jpeg'); }
  const t0 = performance.now();
  const r = await fetch('api/render?' + params);
  if (r.status === 409) return;  // a newer request took over
  if (level === 'baked' && r.status === 404) { state.baked[key] = false; return request('fast'); }
  if (!r.ok) { $('status').textContent = 'error: ' + (await r.text()); return; }
  const blob = await r.blob();
  const t1 = performance.now();
  if (seq < state.shown) return;
  // Decoded before it is shown, so a view counts once it can be painted.
  const url = URL.createObjectURL(blob);
  const decoded = new Image();
  decoded.src = url;
  try { await decoded.decode(); } catch (e) { URL.revokeObjectURL(url); throw e; }
  if (seq < state.shown) { URL.revokeObjectURL(url); return; }
  state.lastBytes = new Uint8Array(await blob.arrayBuffer());
  state.lastFast = fast;
  state.shown = seq;
  const img = $('view');
  if (img.src) URL.revokeObjectURL(img.src);
  img.src = url;
  img.dataset.seq = seq;
  img.dataset.size = w + 'x' + h;
  // Where the time went: the server's stages (its Server-Timing header), the round trip, the decode.
  const server = Object.fromEntries((r.headers.get('Server-Timing') || '').split(',').map((m) => m.trim().split(';dur=')).filter((m) => m.length === 2).map(([k, v]) => [k, Number(v)]));
  state.times.push({ level, trip: t1 - t0, decode: performance.now() - t1, ...server });
  if (state.times.length > 1000) state.times.shift();
  $('status').textContent = { fast: 'moving', baked: 'moving (baked)', mid: 'refining', full: 'refined' }[level] + ': ' + w + 'x' + h + ' in ' +
      Math.round(performance.now() - t0) + ' ms';
  document.body.dataset.rendered = String(Number(document.body.dataset.rendered || 0) + 1);
}

// Once the camera rests: a 256 px step first when the view is larger, then the full view (a
// newer request cancels both).
async function refine() {
  const moves = state.moves;
  if (Math.max(...state.size) > 256) await request('mid');
  if (state.moves === moves) await request('full');  // not when the camera moved meanwhile
}

// While the camera moves: fast views; 250 ms after it rests: the refined one.
function moved() {
  $('truth').hidden = true;
  state.moves = (state.moves || 0) + 1;
  if (!state.baked[frameKey()]) request('fast');
  // Two baked views in flight, so the server marches one while the page receives and decodes the
  // other; past that, the latest camera waits for the next free place.
  else if (state.inflight >= 2) state.pending = true;
  else {
    state.inflight += 1;
    request('baked').finally(() => {
      state.inflight -= 1;
      if (state.pending) { state.pending = false; moved(); }
    });
  }
  clearTimeout(state.timer);
  state.timer = setTimeout(refine, 250);
}

function snap(c) {
  const cam = state.frame.cameras[c];
  camera.position.set(...cam.eye);
  camera.up.set(...cam.up);
  camera.fov = cam.fovy;
  camera.aspect = cam.width / cam.height;
  camera.updateProjectionMatrix();
  const target = new THREE.Vector3(...cam.eye).add(new THREE.Vector3(...cam.forward).multiplyScalar(
      new THREE.Vector3(...cam.eye).distanceTo(new THREE.Vector3(...state.frame.center))));
  if (controls) controls.dispose();
  controls = new THREE.OrbitControls(camera, $('stage'));
  controls.target.copy(target);
  controls.update();
  controls.addEventListener('change', moved);
  state.size = [cam.width, cam.height];
  $('stage').style.height = Math.round(512 * cam.height / cam.width) + 'px';
  refine();
  showTruth(c);
}

// Beside a snapped view: its ground truth, and its PSNR and SSIM as transhuman-eval scores them.
async function showTruth(c) {
  const q = 'human=' + state.human + '&frame=' + state.frames[$('frame').value] + '&camera=' + c;
  $('truth-img').src = 'api/ground_truth?' + q;
  $('score').textContent = 'scoring camera ' + c + ' ...';
  $('truth').hidden = false;
  const r = await json('api/evaluate?' + q);
  $('score').textContent = 'ground truth, camera ' + c + ': PSNR ' + r.psnr.toFixed(2) + ' dB, SSIM ' +
      r.ssim.toFixed(3) + ' (as transhuman-eval scores it)';
  document.body.dataset.psnr = r.psnr;
}

// The frame's bake (started by the first ask): its progress, then views while moving come from it.
async function watchBake() {
  if (!state.info.bake) return;
  const key = frameKey(), frame = state.frames[$('frame').value];
  for (;;) {
    let r;
    try { r = await json('api/bake?human=' + state.human + '&frame=' + frame); } catch (e) {
      $('bake').textContent = 'bake: ' + e.message; return; }
    if (key !== frameKey()) return;  // another frame is shown now
    if (r.state === 'ready') {
      state.baked[key] = true;
      $('bake').textContent = 'frame ' + frame + ' baked (' + (r.voxel * 100).toFixed(1) + ' cm grid, ' + r.bricks +
          ' bricks, ' + r.mib.toFixed(1) + ' MiB, ' + r.seconds.toFixed(1) + ' s): views while moving come from the bake';
      document.body.dataset.baked = key;
      return;
    }
    if (r.state === 'failed') { $('bake').textContent = 'bake failed: ' + r.error; return; }
    $('bake').textContent = r.waiting ? 'frame ' + frame + ' waits to be baked for real-time views'
        : 'baking frame ' + frame + ' for real-time views: ' + Math.round(100 * r.progress) + '%';
    await new Promise((ok) => setTimeout(ok, 300));
  }
}

async function loadFrame() {
  const frame = state.frames[$('frame').value];
  $('frame-label').textContent = frame;
  state.frame = await json('api/frame?human=' + state.human + '&frame=' + frame);
  const snaps = $('snaps');
  snaps.textContent = 'cameras: ';
  state.frame.cameras.forEach((_, c) => {
    const b = document.createElement('button');
    b.textContent = c;
    b.onclick = () => snap(c);
    snaps.append(b);
  });
  const refs = $('refs');
  refs.textContent = 'reference views: ';
  for (let i = 0; i < state.frame.references; ++i) {
    const img = document.createElement('img');
    img.src = 'api/reference?human=' + state.human + '&frame=' + frame + '&index=' + i;
    refs.append(img);
  }
}

async function start() {
  state.info = await json('api/info');
  const sel = $('human');
  state.info.humans.forEach((h, i) => sel.append(new Option(h.name, i)));
  sel.value = state.info.start.human;
  const choose = async (first) => {
    state.human = Number(sel.value);
    state.frames = state.info.humans[state.human].frames.slice();
    const start = state.info.start;
    // --frame: shown first, also when the setting does not list it.
    if (first && start.frame >= 0 && !state.frames.includes(start.frame)) {
      state.frames.push(start.frame);
      state.frames.sort((a, b) => a - b);
    }
    $('frame').max = state.frames.length - 1;
    $('frame').value = first && start.frame >= 0 ? state.frames.indexOf(start.frame) : 0;
    await loadFrame();
    snap(Math.min(state.info.view, state.frame.cameras.length - 1));
  };
  sel.onchange = () => choose().then(watchBake);
  $('frame').oninput = async () => { await loadFrame(); refine(); watchBake(); };
  $('mode').onchange = () => refine();
  await choose(true);
  watchBake();
}
// ?selftest=drag (for tests): once the first view is shown, drags the camera 120 px with
// dispatched mouse events and reports in <body data-selftest> whether fast views came while
// moving, a refined one after, and whether the image changed.
async function selftest() {
  const until = (cond) => new Promise((ok) => { const t = setInterval(() => { if (cond()) { clearInterval(t); ok(); } }, 20); });
  await until(() => Number(document.body.dataset.rendered || 0) >= 1);
  const before = state.lastBytes, shown = Number(document.body.dataset.rendered);
  let fast = 0;
  const stage = $('stage'), box = stage.getBoundingClientRect();
  const at = (dx) => ({ clientX: box.left + box.width / 2 + dx, clientY: box.top + box.height / 2, button: 0, bubbles: true });
  stage.dispatchEvent(new MouseEvent('mousedown', at(0)));
  for (let dx = 10; dx <= 120; dx += 10) {
    document.dispatchEvent(new MouseEvent('mousemove', at(dx)));
    await new Promise((ok) => setTimeout(ok, 60));
    if (state.lastFast) fast += 1;
  }
  document.dispatchEvent(new MouseEvent('mouseup', at(120)));
  await until(() => Number(document.body.dataset.rendered) > shown && !state.lastFast);
  const after = state.lastBytes;
  const changed = before.length !== after.length || before.some((b, i) => b !== after[i]);
  document.body.dataset.selftest = 'fast views while moving: ' + fast + '; refined: yes; image changed: ' + (changed ? 'yes' : 'no');
}
// ?selftest=fps&seconds=S (benchmarks): once the frame is baked, drags the camera for S seconds
// (a mouse move every 16 ms) and reports the views shown per second in <body data-fps> and the
// page's title.
async function selftestFps(seconds) {
  const until = (cond) => new Promise((ok) => { const t = setInterval(() => { if (cond()) { clearInterval(t); ok(); } }, 20); });
  await until(() => Number(document.body.dataset.rendered || 0) >= 1 && document.body.dataset.baked);
  await new Promise((ok) => setTimeout(ok, 1000));  // the refined view of the snap
  const stage = $('stage'), box = stage.getBoundingClientRect();
  const at = (dx) => ({ clientX: box.left + box.width / 2 + dx, clientY: box.top + box.height / 2, button: 0, bubbles: true });
  stage.dispatchEvent(new MouseEvent('mousedown', at(0)));
  const shown0 = Number(document.body.dataset.rendered), t0 = performance.now();
  let dx = 0;
  while (performance.now() - t0 < 1000 * seconds) {
    dx += 2;
    document.dispatchEvent(new MouseEvent('mousemove', at(dx % 400 - 200)));
    await new Promise((ok) => setTimeout(ok, 16));
  }
  const shown = Number(document.body.dataset.rendered) - shown0, elapsed = (performance.now() - t0) / 1000;
  document.dispatchEvent(new MouseEvent('mouseup', at(0)));
  const views = state.times.slice(-shown).filter((t) => t.level === 'baked');
  const median = (key) => { const xs = views.map((t) => t[key]).filter((x) => x >= 0).sort((a, b) => a - b); return xs.length ? xs[xs.length >> 1].toFixed(1) : '?'; };
  document.body.dataset.fps = (shown / elapsed).toFixed(1) + ' views/s (' + shown + ' in ' + elapsed.toFixed(1) + ' s, ' + $('view').dataset.size +
      '); medians per view: round trip ' + median('trip') + ' ms (server: march ' + median('march') + ', encode ' + median('encode') + '), decode ' + median('decode') + ' ms';
  document.title = 'fps: ' + document.body.dataset.fps;  // readable without a DOM dump
}
const query = new URLSearchParams(location.search);
if (query.get('selftest') === 'drag') selftest();
if (query.get('selftest') === 'fps') selftestFps(Number(query.get('seconds') || 4));
start().catch((e) => { $('status').textContent = 'error: ' + e.message; document.body.dataset.error = e.message; });
</script>
</body>
</html>
)HTML";

}  // namespace th::viewer
