// The TransHuman-C++ report page (lib/report/assets/report.js). Draws every section from the
// data lib/report embeds in index.html (window.TH_REPORT): scores, training curve, orbit, mesh
// viewer and gallery for an evaluation or the demo; the side-by-side comparison for ablations.
// No framework; the 3D viewer uses three.js (Debian's libjs-three, copied beside the page).
'use strict';

(function () {
  const R = window.TH_REPORT;
  const SVG = 'http://www.w3.org/2000/svg';
  const COLORS = ['#2563eb', '#dc2626', '#16a34a', '#9333ea', '#ea580c', '#0891b2', '#4b5563'];

  // el('div', {class: 'x'}, child, 'text', ...): a DOM element; attributes starting with "on"
  // are listeners.
  function el(tag, attrs, ...children) {
    const node = tag.startsWith('svg:') ? document.createElementNS(SVG, tag.slice(4)) : document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) {
      if (k.startsWith('on')) node.addEventListener(k.slice(2), v);
      else if (v !== null && v !== undefined) node.setAttribute(k, v);
    }
    for (const c of children.flat()) {
      if (c !== null && c !== undefined) node.append(c instanceof Node ? c : String(c));
    }
    return node;
  }

  const finite = (v) => typeof v === 'number' && isFinite(v);
  const fmt = (v, digits) => (finite(v) ? v.toFixed(digits) : 'n/a');
  const signed = (v, digits) => (finite(v) ? (v > 0 ? '+' : '') + v.toFixed(digits) : 'n/a');

  // One CSV line's fields (RFC 4180: a quoted field may hold commas and doubled quotes).
  function csvFields(line) {
    const out = [];
    for (let i = 0; i <= line.length; ) {
      if (line[i] === '"') {
        let v = '';
        for (i++; i < line.length; ) {
          if (line[i] !== '"') v += line[i++];
          else if (line[i + 1] === '"') (v += '"'), (i += 2);
          else { i++; break; }
        }
        out.push(v);
        i++;  // the comma after the closing quote
      } else {
        const end = line.indexOf(',', i) < 0 ? line.length : line.indexOf(',', i);
        out.push(line.slice(i, end));
        i = end + 1;
      }
    }
    return out;
  }

  // per_image.csv as objects; numeric fields as numbers, "n/a" as null.
  function parseCsv(text) {
    const lines = text.trim().split('\n');
    const keys = csvFields(lines[0]);
    return lines.slice(1).map((line) => {
      const row = {};
      csvFields(line).forEach((v, i) => {
        row[keys[i]] = keys[i] === 'human' ? v : v === 'n/a' ? null : Number(v);
      });
      return row;
    });
  }

  function parseJsonl(text) {
    return text.split('\n').filter((l) => l.trim()).map((l) => JSON.parse(l));
  }

  // The LPIPS mean of a summary.json, or null when the evaluation had no LPIPS weights.
  const lpipsOf = (s) => (s.lpips_available === 'yes' ? s.lpips : null);
  const imageKey = (r) => `${r.human}/${r.frame}/${r.view}`;

  function section(id, title, ...body) {
    return el('section', { id }, el('h2', {}, title), ...body);
  }

  // ---- charts (SVG) ---------------------------------------------------------------------

  function niceTicks(lo, hi, count) {
    const step0 = (hi - lo) / count;
    const mag = Math.pow(10, Math.floor(Math.log10(step0)));
    const step = [1, 2, 5, 10].map((m) => m * mag).find((s) => s >= step0);
    const ticks = [];
    for (let t = Math.ceil(lo / step) * step; t <= hi + step * 1e-9; t += step) ticks.push(Number(t.toPrecision(12)));
    return ticks;
  }

  // A line chart: series = [{name, points: [[x, y], ...], color, dots}].
  function lineChart(series, xLabel, yLabel) {
    const W = 560, H = 260, L = 52, B = 36, T = 12, Rm = 12;
    const pts = series.flatMap((s) => s.points);
    if (!pts.length) return el('p', {}, 'no data');
    let [x0, x1] = [Math.min(...pts.map((p) => p[0])), Math.max(...pts.map((p) => p[0]))];
    let [y0, y1] = [Math.min(...pts.map((p) => p[1])), Math.max(...pts.map((p) => p[1]))];
    if (x1 === x0) x1 = x0 + 1;
    if (y1 === y0) [y0, y1] = [y0 - 0.5, y1 + 0.5];
    const pad = (y1 - y0) * 0.05;
    [y0, y1] = [y0 - pad, y1 + pad];
    const px = (x) => L + ((x - x0) / (x1 - x0)) * (W - L - Rm);
    const py = (y) => H - B - ((y - y0) / (y1 - y0)) * (H - B - T);
    const svg = el('svg:svg', { viewBox: `0 0 ${W} ${H}`, class: 'chart', role: 'img', 'aria-label': yLabel });
    for (const t of niceTicks(y0, y1, 5)) {
      svg.append(el('svg:line', { x1: L, x2: W - Rm, y1: py(t), y2: py(t), class: 'grid' }));
      svg.append(el('svg:text', { x: L - 6, y: py(t) + 4, class: 'tick', 'text-anchor': 'end' }, t));
    }
    for (const t of niceTicks(x0, x1, 6)) {
      svg.append(el('svg:text', { x: px(t), y: H - B + 16, class: 'tick', 'text-anchor': 'middle' }, t));
    }
    svg.append(el('svg:text', { x: (L + W) / 2, y: H - 4, class: 'label', 'text-anchor': 'middle' }, xLabel));
    svg.append(el('svg:text', { x: 12, y: (T + H - B) / 2, class: 'label', 'text-anchor': 'middle',
      transform: `rotate(-90 12 ${(T + H - B) / 2})` }, yLabel));
    series.forEach((s, i) => {
      const color = s.color || COLORS[i % COLORS.length];
      if (s.dots) {
        for (const [x, y] of s.points) svg.append(el('svg:circle', { cx: px(x), cy: py(y), r: 3.5, fill: color }));
      } else {
        const d = s.points.map(([x, y], j) => `${j ? 'L' : 'M'}${px(x).toFixed(1)},${py(y).toFixed(1)}`).join('');
        svg.append(el('svg:path', { d, stroke: color, fill: 'none', 'stroke-width': 1.5 }));
      }
    });
    const legend = el('p', { class: 'legend' },
      series.map((s, i) => el('span', { style: `color:${s.color || COLORS[i % COLORS.length]}` }, `■ ${s.name} `)));
    return el('figure', { class: 'chart' }, svg, legend);
  }

  // A bar chart of one value per row (starting at zero), with the values written on the bars.
  function barChart(rows, title, digits) {
    const W = 360, H = 220, B = 48, T = 22, L = 8;
    const values = rows.map((r) => r.value).filter(finite);
    const svg = el('svg:svg', { viewBox: `0 0 ${W} ${H}`, class: 'chart bars', role: 'img', 'aria-label': title });
    svg.append(el('svg:text', { x: W / 2, y: 14, class: 'label', 'text-anchor': 'middle' }, title));
    if (!values.length) {
      svg.append(el('svg:text', { x: W / 2, y: H / 2, class: 'tick', 'text-anchor': 'middle' }, 'n/a'));
      return svg;
    }
    const top = Math.max(...values) * 1.1 || 1;
    const bw = (W - 2 * L) / rows.length;
    rows.forEach((r, i) => {
      const x = L + i * bw + bw * 0.15, w = bw * 0.7;
      if (finite(r.value)) {
        const h = (r.value / top) * (H - B - T);
        svg.append(el('svg:rect', { x, y: H - B - h, width: w, height: h, fill: COLORS[i % COLORS.length] }));
        svg.append(el('svg:text', { x: x + w / 2, y: H - B - h - 4, class: 'tick', 'text-anchor': 'middle' }, fmt(r.value, digits)));
      }
      svg.append(el('svg:text', { x: x + w / 2, y: H - B + 14, class: 'tick', 'text-anchor': 'middle' }, r.name));
    });
    return svg;
  }

  // ---- evaluation / demo sections -------------------------------------------------------

  // What rendered an evaluation's views (summaries written before it was recorded: exact).
  const rendererOf = (s) => s.renderer || 'exact';
  const MIXED_RENDERERS = 'These scores come from different renderers: a baked score approximates ' +
    'the exact renderer\'s (the bake samples the field on a grid and interpolates between its ' +
    'points; docs/METHOD.md, section 7.1), so scores of different renderers are not compared row ' +
    'by row.';

  // One table per renderer: scores of the exact renderer and of a bake never share a table.
  function scoresSection(evals) {
    const groups = new Map();
    evals.forEach((e) => {
      const s = JSON.parse(e.summary);
      const r = rendererOf(s);
      if (!groups.has(r)) groups.set(r, []);
      groups.get(r).push({ e, s });
    });
    const table = (list) => {
      const head = el('tr', {}, ['setting', 'renderer', 'images', 'PSNR ↑', 'SSIM ↑', 'LPIPS ↓', 's / image', 'files']
        .map((h) => el('th', {}, h)));
      const rows = list.map(({ e, s }) => {
        const files = Object.entries(e.files).map(([name, href]) => el('a', { href }, name));
        return el('tr', { 'data-setting': s.setting, 'data-renderer': rendererOf(s) },
          el('td', {}, s.setting),
          el('td', { 'data-key': 'renderer' }, rendererOf(s)),
          el('td', { 'data-key': 'images' }, s.images),
          el('td', { 'data-key': 'psnr' }, fmt(s.psnr, 2)),
          el('td', { 'data-key': 'ssim' }, fmt(s.ssim, 3)),
          el('td', { 'data-key': 'lpips' }, fmt(lpipsOf(s), 3)),
          el('td', {}, fmt(s.seconds_per_image, 2)),
          el('td', { class: 'files' }, files));
      });
      return el('table', { class: 'scores-table', id: groups.size === 1 ? 'scores-table' : null },
        el('thead', {}, head), el('tbody', {}, rows));
    };
    const parts = [];
    if (groups.size > 1) {
      parts.push(el('p', { class: 'note', id: 'mixed-renderers' }, MIXED_RENDERERS));
      groups.forEach((list, r) => parts.push(el('h3', {}, `Renderer: ${r}`), table(list)));
    } else {
      groups.forEach((list) => parts.push(table(list)));
    }
    if (evals.some((e) => lpipsOf(JSON.parse(e.summary)) === null))
      parts.push(el('p', { class: 'note' }, 'LPIPS n/a: no LPIPS weights were available (scripts/export_lpips.py makes them).'));
    return section('scores', 'Scores', ...parts);
  }

  function trainingSection(text) {
    const lines = parseJsonl(text);
    const steps = lines.filter((l) => finite(l.loss));
    const val = lines.filter((l) => finite(l.val_psnr));
    const xy = (list, key) => list.filter((l) => finite(l[key])).map((l) => [l.step, l[key]]);
    const last = steps[steps.length - 1];
    return section('training', 'Training',
      el('div', { class: 'charts' },
        lineChart([{ name: 'training loss', points: xy(steps, 'loss') }], 'step', 'loss'),
        lineChart([
          { name: 'training batch PSNR', points: xy(steps, 'psnr') },
          { name: `validation PSNR (${[...new Set(val.map((l) => l.val_renderer || 'exact'))].join(' + ')})`,
            points: xy(val, 'val_psnr'), color: COLORS[1], dots: true },
        ], 'step', 'PSNR (dB)')),
      last ? el('p', { class: 'note' }, `${steps.length} logged steps, last step ${last.step}` +
        (val.length ? `; last validation PSNR ${fmt(val[val.length - 1].val_psnr, 2)} dB ` +
          `(${val[val.length - 1].val_renderer || 'exact'} renderer)` : '')) : null);
  }

  // The orbit as a flip-book of its frames (browsers do not play the MPEG-4 Part 2 video
  // OpenCV writes), with a link to the video itself.
  function orbitSection(orbit) {
    if (!orbit.frames.length) return null;
    const img = el('img', { src: orbit.frames[0], class: 'orbit', alt: 'orbit frame' });
    const slider = el('input', { type: 'range', min: 0, max: orbit.frames.length - 1, value: 0 });
    let timer = null;
    const show = (i) => { slider.value = i; img.src = orbit.frames[i]; };
    slider.addEventListener('input', () => show(Number(slider.value)));
    const play = el('button', {
      onclick: () => {
        if (timer) { clearInterval(timer); timer = null; play.textContent = 'play'; return; }
        play.textContent = 'pause';
        timer = setInterval(() => show((Number(slider.value) + 1) % orbit.frames.length), 1000 / 12);
      },
    }, 'play');
    return section('orbit', 'Orbit', img, el('div', { class: 'controls' }, play, slider),
      el('p', { class: 'note' }, `${orbit.frames.length} views`, orbit.video ? [' · ', el('a', { href: orbit.video }, 'video.mp4')] : null));
  }

  // The mesh in three.js: orbit (left drag), zoom (wheel), pan (right drag), vertex colours.
  // ?lighting=0 shows the colours unlit; ?view=mesh shows the viewer alone, filling the window.
  function meshSection(mesh, params) {
    const box = el('div', { class: 'viewer', id: 'viewer' });
    const lit = el('input', { type: 'checkbox', id: 'lighting' });
    lit.checked = params.get('lighting') !== '0';
    const full = params.get('view') === 'mesh' ? el('a', { href: '?' }, 'whole report') : el('a', { href: '?view=mesh' }, 'viewer alone');
    const s = section('mesh', 'Mesh', box,
      el('div', { class: 'controls' }, el('label', {}, lit, ' lighting'), ' · ', full, ' · ',
        el('a', { href: mesh.file }, mesh.file)),
      el('p', { class: 'note', id: 'mesh-info' }, 'drag to orbit, wheel to zoom, right-drag to pan'));
    if (!mesh.viewer || !window.THREE || !THREE.PLYLoader || !THREE.OrbitControls) {
      box.append(el('p', { class: 'note' }, 'No 3D viewer: three.js was not found when the report was written (Debian: apt-get install libjs-three).'));
      return s;
    }
    // Started once the box is in the document (it needs a size).
    s.startViewer = () => startViewer(box, lit, s.querySelector('#mesh-info'));
    return s;
  }

  function startViewer(box, lit, info) {
    const bytes = Uint8Array.from(atob(window.TH_MESH_PLY), (c) => c.charCodeAt(0));
    const geometry = new THREE.PLYLoader().parse(bytes.buffer);
    geometry.computeVertexNormals();
    geometry.computeBoundingBox();
    const colored = !!geometry.getAttribute('color');
    const header = new TextDecoder().decode(bytes.subarray(0, 512));
    const bb = geometry.boundingBox, size = bb.getSize(new THREE.Vector3()), center = bb.getCenter(new THREE.Vector3());
    // Up: the direction transhuman-mesh records in the header, else the box's longest axis.
    const m = header.match(/, up (-?[\d.e+-]+) (-?[\d.e+-]+) (-?[\d.e+-]+)/);
    const up = m ? new THREE.Vector3(+m[1], +m[2], +m[3]).normalize()
      : new THREE.Vector3(...['x', 'y', 'z'].map((a) => (size[a] === Math.max(size.x, size.y, size.z) ? 1 : 0)));

    const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    renderer.setPixelRatio(window.devicePixelRatio);
    box.append(renderer.domElement);
    const scene = new THREE.Scene();
    scene.background = new THREE.Color(0x1e2430);
    const base = { color: colored ? 0xffffff : 0xb0b0b0, vertexColors: colored ? THREE.VertexColors : THREE.NoColors, side: THREE.DoubleSide };
    const materials = { lit: new THREE.MeshLambertMaterial(base), flat: new THREE.MeshBasicMaterial(base) };
    const object = new THREE.Mesh(geometry, lit.checked ? materials.lit : materials.flat);
    scene.add(object);
    scene.add(new THREE.AmbientLight(0xffffff, 0.45));
    const radius = size.length() / 2;
    const camera = new THREE.PerspectiveCamera(35, 1, radius / 100, radius * 100);
    camera.up.copy(up);
    // A key light that moves with the camera: from its upper left, shining along its view.
    const key = new THREE.DirectionalLight(0xffffff, 0.75);
    key.position.set(-0.6, 0.8, 0);
    key.target.position.set(0, 0, -1);
    camera.add(key, key.target);
    scene.add(camera);
    // Start level, 3.2 radii away, along the thinner horizontal axis: facing the body's wide side.
    const side = ['x', 'y', 'z'].map((a) => new THREE.Vector3(a === 'x' ? 1 : 0, a === 'y' ? 1 : 0, a === 'z' ? 1 : 0))
      .filter((a) => Math.abs(a.dot(up)) < 0.9)
      .sort((a, b) => Math.abs(b.dot(size)) - Math.abs(a.dot(size)))[1] || new THREE.Vector3(1, 0, 0);
    const home = center.clone().add(side.clone().multiplyScalar(radius * 3.2));
    camera.position.copy(home);
    const controls = new THREE.OrbitControls(camera, renderer.domElement);
    controls.target.copy(center);

    const render = () => renderer.render(scene, camera);
    const resize = () => {
      const w = box.clientWidth, h = box.clientHeight;
      renderer.setSize(w, h);
      camera.aspect = w / h;
      camera.updateProjectionMatrix();
      render();
    };
    controls.addEventListener('change', render);
    lit.addEventListener('change', () => { object.material = lit.checked ? materials.lit : materials.flat; render(); });
    window.addEventListener('resize', resize);
    controls.update();
    resize();
    const count = geometry.getAttribute('position').count;
    const faces = geometry.index ? geometry.index.count / 3 : count / 3;
    info.textContent = `${count.toLocaleString('en')} vertices, ${faces.toLocaleString('en')} faces` +
      `${colored ? ', vertex colours' : ', no colours in the file'} · drag to orbit, wheel to zoom, right-drag to pan`;
    document.body.dataset.viewer = 'rendered';
  }

  // Every evaluated view: its panel (prediction | ground truth | input views | error map) and
  // scores, sortable so the worst views are one click away.
  function gallerySection(evals) {
    const items = [];
    for (const e of evals) {
      const s = JSON.parse(e.summary);
      parseCsv(e.per_image).forEach((r, i) => items.push({ r, setting: s.setting, renderer: r.renderer || rendererOf(s), panel: e.panels[i] }));
    }
    const grid = el('div', { class: 'gallery', id: 'gallery' });
    const cards = items.map(({ r, setting, renderer, panel }) => el('figure', {
      class: 'card', 'data-psnr': r.psnr, 'data-key': `${setting}/${renderer}/${imageKey(r)}`, 'data-renderer': renderer,
    },
    panel ? el('a', { href: panel }, el('img', { src: panel, loading: 'lazy', alt: imageKey(r) })) : el('p', { class: 'note' }, 'no panel saved'),
    el('figcaption', {}, `${r.human} · frame ${r.frame} · view ${r.view} · `, el('b', {}, `${fmt(r.psnr, 2)} dB`),
      ` · SSIM ${fmt(r.ssim, 3)}`, finite(r.lpips) ? ` · LPIPS ${fmt(r.lpips, 3)}` : '', ` · ${renderer}`)));
    const order = el('select', { id: 'gallery-order' },
      el('option', { value: 'worst' }, 'PSNR, worst first'),
      el('option', { value: 'best' }, 'PSNR, best first'),
      el('option', { value: 'name' }, 'person, frame, view'));
    // Scores of different renderers are never ranked together: one renderer's views at a time.
    const renderers = [...new Set(items.map((i) => i.renderer))];
    const shown = renderers.length > 1
      ? el('select', { id: 'gallery-renderer' }, renderers.map((r) => el('option', { value: r }, r)))
      : null;
    const sortBy = (how) => {
      const sorted = cards.filter((c) => !shown || c.dataset.renderer === shown.value);
      if (how !== 'name') sorted.sort((a, b) => (a.dataset.psnr - b.dataset.psnr) * (how === 'worst' ? 1 : -1));
      grid.replaceChildren(...sorted);
    };
    order.addEventListener('change', () => sortBy(order.value));
    if (shown) shown.addEventListener('change', () => sortBy(order.value));
    sortBy('worst');
    return section('gallery-section', `Every evaluated view (${cards.length})`,
      el('p', { class: 'controls' }, shown ? ['renderer: ', shown, ' '] : null, 'order: ', order,
        el('span', { class: 'note' }, ' · each panel: prediction | ground truth | input views | error map')),
      grid);
  }

  // ---- ablation page ----------------------------------------------------------------------

  // Per image, full minus the row (matched by person, frame and view): mean, standard error and
  // on how many images `full` is better ("better" is lower for LPIPS).
  function paired(fullRows, rowRows, key) {
    const byKey = new Map(rowRows.map((r) => [imageKey(r), r]));
    const d = [];
    for (const f of fullRows) {
      const r = byKey.get(imageKey(f));
      if (r && finite(f[key]) && finite(r[key])) d.push(f[key] - r[key]);
    }
    if (!d.length) return null;
    const mean = d.reduce((a, b) => a + b, 0) / d.length;
    const sd = Math.sqrt(d.reduce((a, b) => a + (b - mean) ** 2, 0) / Math.max(1, d.length - 1));
    const better = d.filter((v) => (key === 'lpips' ? v < 0 : v > 0)).length;
    return { mean, se: sd / Math.sqrt(d.length), better, n: d.length, d };
  }

  // The paired PSNR differences of one row, sorted, one bar per image (above zero: full better).
  function diffStrip(p) {
    const W = 360, H = 90, M = 4;
    const d = p.d.slice().sort((a, b) => a - b);
    const top = Math.max(...d.map(Math.abs)) || 1;
    const svg = el('svg:svg', { viewBox: `0 0 ${W} ${H}`, class: 'chart strip', role: 'img', 'aria-label': 'paired differences' });
    svg.append(el('svg:line', { x1: 0, x2: W, y1: H / 2, y2: H / 2, class: 'grid' }));
    const bw = (W - 2 * M) / d.length;
    d.forEach((v, i) => {
      const h = (Math.abs(v) / top) * (H / 2 - 14);  // room for the scale label
      svg.append(el('svg:rect', { x: M + i * bw, width: Math.max(bw - 0.5, 0.5), y: v > 0 ? H / 2 - h : H / 2, height: h,
        fill: v > 0 ? COLORS[2] : COLORS[1] }));
    });
    svg.append(el('svg:text', { x: W - 2, y: 11, class: 'tick', 'text-anchor': 'end' }, `±${top.toFixed(2)}`));
    return svg;
  }

  function ablationPage(rows) {
    const parsed = rows.map((r) => ({ ...r, s: JSON.parse(r.summary), images: parseCsv(r.per_image) }));
    const head = el('tr', {}, ['row', 'what changes', 'renderer', 'images', 'PSNR ↑', 'SSIM ↑', 'LPIPS ↓', 'train time', 'page']
      .map((h) => el('th', {}, h)));
    const renderers = new Set(parsed.map((r) => rendererOf(r.s)));
    const body = parsed.map((r) => el('tr', { 'data-setting': r.name, 'data-renderer': rendererOf(r.s) },
      el('td', {}, el('code', {}, r.name)), el('td', { class: 'text' }, r.description),
      el('td', { 'data-key': 'renderer' }, rendererOf(r.s)),
      el('td', { 'data-key': 'images' }, r.s.images), el('td', { 'data-key': 'psnr' }, fmt(r.s.psnr, 2)),
      el('td', { 'data-key': 'ssim' }, fmt(r.s.ssim, 3)), el('td', { 'data-key': 'lpips' }, fmt(lpipsOf(r.s), 3)),
      el('td', {}, finite(r.train_seconds) ? `${(r.train_seconds / 60).toFixed(1)} min` : 'n/a'),
      el('td', {}, r.page ? el('a', { href: r.page }, 'open') : '')));
    const out = [section('scores', `Rows (setting ${parsed[0].s.setting})`,
      renderers.size > 1 ? el('p', { class: 'note', id: 'mixed-renderers' }, MIXED_RENDERERS +
        ' Bars and paired differences below compare rows of one renderer only where marked.') : null,
      el('table', { id: 'scores-table' }, el('thead', {}, head), el('tbody', {}, body)))];
    const metrics = [['psnr', 'PSNR (dB) ↑', 2], ['ssim', 'SSIM ↑', 3], ['lpips', 'LPIPS ↓', 3]];
    out.push(section('bars', 'Per metric', el('div', { class: 'charts' }, metrics.map(([key, title, digits]) =>
      barChart(parsed.map((r) => ({ name: renderers.size > 1 ? `${r.name} (${rendererOf(r.s)})` : r.name, value: key === 'lpips' ? lpipsOf(r.s) : r.s[key] })), title, digits)))));

    const full = parsed.find((r) => r.name === 'full');
    if (full && parsed.length > 1) {
      const dhead = el('tr', {}, ['row', 'images paired', 'PSNR: full − row', 'full better', 'SSIM: full − row', 'full better',
        'LPIPS: full − row', 'full better', 'PSNR differences, sorted'].map((h) => el('th', {}, h)));
      // Pairs of one renderer only: another renderer's difference is not the ablation's.
      const other = parsed.filter((r) => r !== full && rendererOf(r.s) !== rendererOf(full.s));
      const drows = parsed.filter((r) => r !== full && rendererOf(r.s) === rendererOf(full.s)).map((r) => {
        const cells = [el('td', {}, el('code', {}, r.name))];
        const ps = metrics.map(([key, , digits]) => [paired(full.images, r.images, key), digits]);
        cells.push(el('td', {}, ps[0][0] ? ps[0][0].n : 0));
        for (const [p, digits] of ps) {
          cells.push(el('td', {}, p ? `${signed(p.mean, digits)} (s.e. ${fmt(p.se, digits)})` : 'n/a'));
          cells.push(el('td', {}, p ? `${p.better}/${p.n}` : 'n/a'));
        }
        cells.push(el('td', {}, ps[0][0] ? diffStrip(ps[0][0]) : ''));
        return el('tr', { 'data-row': r.name }, cells);
      });
      out.push(section('paired', 'Paired per image against full',
        el('p', { class: 'note' }, 'Each image of a row is compared with the same image (person, frame, view) under full. ' +
          'Strip: one bar per image, green where full is better, red where the row is.'),
        other.length ? el('p', { class: 'note', id: 'paired-other-renderer' }, `Not paired (rendered by another ` +
          `renderer than full's ${rendererOf(full.s)}): ${other.map((r) => `${r.name} (${rendererOf(r.s)})`).join(', ')}.`) : null,
        el('table', { id: 'paired-table' }, el('thead', {}, dhead), el('tbody', {}, drows))));
    } else {
      out.push(el('p', { class: 'note' }, 'No row named full: no paired differences.'));
    }
    return out;
  }

  // ---- the page ---------------------------------------------------------------------------

  function meta() {
    const m = document.getElementById('meta');
    m.append(`written ${R.generated} · commit ${R.commit}`);
    for (const [label, href] of R.links) m.append(' · ', el('a', { href }, label));
    if (R.config) {
      document.querySelector('header').append(el('details', {}, el('summary', {}, 'configuration (config.yaml)'),
        el('pre', { class: 'config' }, R.config)));
    }
  }

  function build() {
    const main = document.getElementById('report');
    const params = new URLSearchParams(location.search);
    meta();
    if (R.kind === 'ablation') {
      main.append(...ablationPage(R.rows));
      return;
    }
    const mesh = R.mesh ? meshSection(R.mesh, params) : null;
    if (params.get('view') === 'mesh' && mesh) {
      document.body.classList.add('viewer-only');
      main.append(mesh);
    } else {
      const nav = el('nav', {}, [['scores', 'scores'], R.metrics && ['training', 'training'], R.orbit && ['orbit', 'orbit'],
        mesh && ['mesh', 'mesh'], ['gallery-section', 'gallery']].filter(Boolean).map(([id, label]) => el('a', { href: `#${id}` }, label)));
      const sections = [nav, scoresSection(R.evals), R.metrics ? trainingSection(R.metrics) : null,
        R.orbit ? orbitSection(R.orbit) : null, mesh, gallerySection(R.evals)];
      main.append(...sections.filter(Boolean));
    }
    if (mesh && mesh.startViewer) mesh.startViewer();
  }

  try {
    build();
  } catch (e) {
    window.TH_ERRORS.push(`report.js: ${e && e.stack ? e.stack : e}`);
    console.error(e);
  }
  // What a test (or a curious user) reads back: errors, and that the page finished building.
  document.getElementById('th-errors').textContent = window.TH_ERRORS.join('\n');
  document.body.dataset.ready = window.TH_ERRORS.length ? 'errors' : 'yes';
  document.body.dataset.buildMs = Math.round(performance.now());
  window.addEventListener('load', () => { document.body.dataset.loadMs = Math.round(performance.now()); });
})();
