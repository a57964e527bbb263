// The page of `perf view` (viewer/view_server.h): reads the workspace through the server's fixed
// routes and draws it with three.js (Debian's libjs-three). Works offline; polls the solve's log
// so that a running solve's curve grows. Test hooks: body[data-cameras] (frusta drawn),
// body[data-views] (held-out rows), body[data-mesh] (loaded, missing or failed),
// body[data-ready] (1 once everything has been asked for and answered); the field's are
// field_view.js's.
'use strict';

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const only = params.get('layers');  // e.g. ?layers=mesh: draw only those layers
const COLOURS = { train: 0x9aa0a6, test: 0xffa94d, excluded: 0xff4d4f, refined: 0x51cf66 };
const LEVEL_COLOURS = ['#4dabf7', '#51cf66', '#ffa94d', '#ff6b6b', '#cc5de8', '#ffd43b'];

async function getJson(url) {
  try {
    const r = await fetch(url, { cache: 'no-store' });
    return r.ok ? await r.json() : null;
  } catch (e) {
    return null;
  }
}

function fmt(v, digits) { return typeof v === 'number' ? v.toFixed(digits) : '-'; }
function stemOf(image) {  // export.h OutputName: the path below images/ without its extension
  let p = image.path.startsWith('images/') ? image.path.slice(7) : image.path.split('/').pop();
  return p.replace(/\.[^./]*$/, '');
}
function fileUrl(rel) { return '/files/' + rel.split('/').map(encodeURIComponent).join('/'); }

// ---------------------------------------------------------------- 3-D view
const layers = {};
function layer(name, scene) {
  const g = new THREE.Group();
  g.name = name;
  g.visible = !only || only.split(',').includes(name);
  scene.add(g);
  layers[name] = g;
  return g;
}

function matrixOf(rows) {  // scene.json's row-major 3x4 [R | c] as a THREE.Matrix4
  const m = new THREE.Matrix4();
  m.set(rows[0][0], rows[0][1], rows[0][2], rows[0][3],
        rows[1][0], rows[1][1], rows[1][2], rows[1][3],
        rows[2][0], rows[2][1], rows[2][2], rows[2][3],
        0, 0, 0, 1);
  return m;
}

// A camera's frustum at `depth` in front of it (pinhole, +z forward, y down): 8 segments.
function frustum(pose, cam, depth, colour) {
  const m = matrixOf(pose);
  const c = new THREE.Vector3(0, 0, 0).applyMatrix4(m);
  const corners = [[0, 0], [cam.width, 0], [cam.width, cam.height], [0, cam.height]].map(([x, y]) =>
    new THREE.Vector3((x - cam.cx) / cam.fx * depth, (y - cam.cy) / cam.fy * depth, depth).applyMatrix4(m));
  const pts = [];
  for (let i = 0; i < 4; ++i) pts.push(c, corners[i], corners[i], corners[(i + 1) % 4]);
  const geo = new THREE.BufferGeometry().setFromPoints(pts);
  return { lines: new THREE.LineSegments(geo, new THREE.LineBasicMaterial({ color: colour })), corners };
}

// The photo on the frustum's far rectangle.
function photoQuad(corners, url) {
  const geo = new THREE.BufferGeometry();
  const p = [corners[0], corners[1], corners[2], corners[0], corners[2], corners[3]];
  geo.setAttribute('position', new THREE.Float32BufferAttribute(p.flatMap((v) => [v.x, v.y, v.z]), 3));
  geo.setAttribute('uv', new THREE.Float32BufferAttribute([0, 1, 1, 1, 1, 0, 0, 1, 1, 0, 0, 0], 2));
  const tex = new THREE.TextureLoader().load(url);
  tex.minFilter = THREE.LinearFilter;
  return new THREE.Mesh(geo, new THREE.MeshBasicMaterial({ map: tex, side: THREE.DoubleSide, transparent: true, opacity: 0.9 }));
}

function drawScene(scene3, sc, points, onMesh) {
  const box = sc.box;
  const centre = new THREE.Vector3(...box.center);
  // The box: its edges, rotated (world_from_box).
  const boxGroup = layer('box', scene3);
  const edges = new THREE.LineSegments(new THREE.EdgesGeometry(new THREE.BoxBufferGeometry(...box.size)),
                                       new THREE.LineBasicMaterial({ color: 0x74c0fc }));
  const r = box.rotation;
  edges.applyMatrix(new THREE.Matrix4().set(r[0][0], r[0][1], r[0][2], box.center[0], r[1][0], r[1][1], r[1][2],
                                            box.center[1], r[2][0], r[2][1], r[2][2], box.center[2], 0, 0, 0, 1));
  boxGroup.add(edges);
  // The shells (the outermost are far: drawn, but the view frames the box and the cameras).
  const shellGroup = layer('shells', scene3);
  for (const radius of sc.shells.radii) {
    const s = new THREE.LineSegments(new THREE.WireframeGeometry(new THREE.SphereBufferGeometry(radius, 24, 12)),
                                     new THREE.LineBasicMaterial({ color: 0x495057, transparent: true, opacity: 0.2 }));
    s.position.set(...sc.shells.center);
    shellGroup.add(s);
  }
  // The cameras: the imported pose by split, the refined one in green beside it.
  const cams = new Map(sc.cameras.map((c) => [c.id, c]));
  const distances = sc.images.map((im) => new THREE.Vector3(im.world_from_cam[0][3], im.world_from_cam[1][3],
                                                            im.world_from_cam[2][3]).distanceTo(centre));
  distances.sort((a, b) => a - b);
  const depth = 0.15 * (distances[Math.floor(distances.length / 2)] || 1);
  const camGroup = layer('cameras', scene3), photoGroup = layer('photos', scene3);
  let drawn = 0, refined = 0;
  for (const im of sc.images) {
    const cam = cams.get(im.camera_id);
    const f = frustum(im.world_from_cam, cam, depth, COLOURS[im.split] || COLOURS.train);
    f.lines.userData = { name: im.name, split: im.split };
    camGroup.add(f.lines);
    ++drawn;
    if (im.refined_world_from_cam) {
      const scaled = Object.assign({}, cam);
      if (im.refined_focal_scale) { scaled.fx *= im.refined_focal_scale; scaled.fy *= im.refined_focal_scale; }
      camGroup.add(frustum(im.refined_world_from_cam, scaled, depth, COLOURS.refined).lines);
      ++refined;
    }
    if (sc.images.length <= 400) photoGroup.add(photoQuad(f.corners, fileUrl(im.path)));
  }
  document.body.dataset.cameras = drawn;
  $('counts').textContent = `${drawn} cameras (${sc.images.filter((i) => i.split === 'train').length} training, ` +
    `${sc.images.filter((i) => i.split === 'test').length} held out, ` +
    `${sc.images.filter((i) => i.split === 'excluded').length} left out)` + (refined ? `, ${refined} refined` : '');
  // The sparse points of the COLMAP model.
  const pointGroup = layer('points', scene3);
  if (points && points.count > 0) {
    const geo = new THREE.BufferGeometry();
    geo.setAttribute('position', new THREE.Float32BufferAttribute(points.xyz, 3));
    geo.setAttribute('color', new THREE.Float32BufferAttribute(points.rgb.map((v) => v / 255), 3));
    pointGroup.add(new THREE.Points(geo, new THREE.PointsMaterial({ size: 2, sizeAttenuation: false, vertexColors: THREE.VertexColors })));
  }
  // The mesh (mesh.glb), lit by its own colours.
  const meshGroup = layer('mesh', scene3);
  new THREE.GLTFLoader().load('/files/mesh.glb', (gltf) => {
    gltf.scene.traverse((o) => {
      if (o.isMesh && o.material) {
        const m = o.material;
        o.material = new THREE.MeshBasicMaterial({ map: m.map || null, vertexColors: m.vertexColors,
                                                    color: m.map ? 0xffffff : m.color });
      }
    });
    meshGroup.add(gltf.scene);
    onMesh('loaded');
  }, undefined, () => onMesh('missing'));
  return { centre, depth, extent: Math.max(...box.size) };
}

function startViewer(sc, points, onMesh) {
  const canvas = $('scene3d');
  // Transparent: the fitted field (field_view.js) is drawn behind it.
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true, alpha: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setClearColor(0x000000, 0);
  const scene3 = new THREE.Scene();
  const frame = drawScene(scene3, sc, points, onMesh);
  const camera = new THREE.PerspectiveCamera(45, 1, frame.extent * 0.01, frame.extent * 200);
  // Looking at the box from above the cameras' mean direction, far enough to see them.
  const mean = new THREE.Vector3();
  for (const im of sc.images) mean.add(new THREE.Vector3(im.world_from_cam[0][3], im.world_from_cam[1][3], im.world_from_cam[2][3]));
  mean.divideScalar(Math.max(1, sc.images.length));
  let dir = mean.clone().sub(frame.centre);
  if (dir.length() < 1e-9) dir = new THREE.Vector3(1, 1, 1);
  // Far enough to see the box and the cameras it was fitted from (left-out ones may be far off).
  const distances = sc.images.filter((im) => im.split !== 'excluded').map((im) =>
    new THREE.Vector3(im.world_from_cam[0][3], im.world_from_cam[1][3], im.world_from_cam[2][3]).distanceTo(frame.centre));
  distances.sort((a, b) => a - b);
  const reach = Math.max(frame.extent, distances.length ? distances[Math.floor(distances.length * 0.9)] : 0);
  // Without the cameras (?layers=mesh, ?layers=field, ...): close to the box.
  const close = only !== null && !only.split(',').includes('cameras');
  camera.position.copy(frame.centre).add(dir.normalize().multiplyScalar(close ? frame.extent * 1.6 : reach * 2.7));
  // Up: the cameras' mean up (-y of each camera in the world).
  const up = new THREE.Vector3();
  for (const im of sc.images) up.add(new THREE.Vector3(-im.world_from_cam[0][1], -im.world_from_cam[1][1], -im.world_from_cam[2][1]));
  if (up.length() > 1e-9) camera.up.copy(up.normalize());
  camera.lookAt(frame.centre);
  const controls = new THREE.OrbitControls(camera, canvas);
  controls.target.copy(frame.centre);
  const resize = () => {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    renderer.setSize(w, h, false);
    camera.aspect = w / Math.max(1, h);
    camera.updateProjectionMatrix();
  };
  window.addEventListener('resize', resize);
  resize();
  // Fly: W A S D Q E move the camera and its orbit target together by a twentieth of the orbit's
  // distance (Shift: four times that); a moved camera leaves a photo's view as a drag does.
  window.addEventListener('keydown', (ev) => {
    if (typeof PerfFieldView === 'undefined' || /^(INPUT|SELECT|TEXTAREA)$/.test(ev.target.tagName || '')) return;
    camera.updateMatrixWorld();
    const e = camera.matrixWorld.elements;
    const step = 0.05 * camera.position.distanceTo(controls.target) * (ev.shiftKey ? 4 : 1);
    const move = PerfFieldView.flyMove(ev.key, [e[0], e[1], e[2]], [e[4], e[5], e[6]], [e[8], e[9], e[10]], step);
    if (!move) return;
    ev.preventDefault();
    controls.dispatchEvent({ type: 'start' });
    const d = new THREE.Vector3(move[0], move[1], move[2]);
    camera.position.add(d);
    controls.target.add(d);
    controls.update();
    controls.dispatchEvent({ type: 'end' });
  });
  for (const box of document.querySelectorAll('#legend input[data-layer]')) {
    const name = box.dataset.layer;
    box.checked = !only || only.split(',').includes(name);
    box.addEventListener('change', () => { if (layers[name]) layers[name].visible = box.checked; });
  }
  const loop = () => {
    controls.update();
    renderer.render(scene3, camera);
    requestAnimationFrame(loop);
  };
  loop();
  return { camera, controls };
}

// ---------------------------------------------------------------- panels
function fillScores(sc, report) {
  const body = $('psnr-table').querySelector('tbody');
  body.innerHTML = '';
  if (!report) {
    $('scores').textContent = 'No report.json yet (perf eval, or the end of perf run, writes it).';
    document.body.dataset.views = 0;
    return;
  }
  const m = report.mean || {};
  $('scores').textContent = `mean of ${report.test_views.length} views: ${fmt(m.psnr, 2)} dB, SSIM ${fmt(m.ssim, 3)}, ` +
    `${fmt(m.psnr_masked, 2)} dB in the mask`;
  const byName = new Map(sc.images.map((im) => [im.name, im]));
  const strip = $('view-strip');
  strip.innerHTML = '';
  for (const v of report.test_views) {
    const tr = document.createElement('tr');
    tr.innerHTML = `<td></td><td>${fmt(v.psnr, 2)}</td><td>${fmt(v.ssim, 3)}</td><td>${fmt(v.psnr_masked, 2)}</td>`;
    tr.firstChild.textContent = v.name;
    body.appendChild(tr);
    const im = byName.get(v.name);
    if (!im) continue;
    const stem = stemOf(im);
    const row = document.createElement('div');
    row.className = 'view-row';
    for (const [label, url] of [['render', fileUrl(`renders/test/${stem}.png`)], ['photo', fileUrl(im.path)],
                                ['mask', fileUrl(`masks/binary/${stem}.png`)], ['cut-out', fileUrl(`foreground/${stem}.png`)]]) {
      const fig = document.createElement('figure');
      const img = document.createElement('img');
      img.src = url;
      img.alt = `${label} of ${v.name}`;
      img.onerror = () => { fig.style.display = 'none'; };
      const cap = document.createElement('figcaption');
      cap.textContent = label === 'render' ? `${v.name}: ${fmt(v.psnr, 2)} dB, SSIM ${fmt(v.ssim, 3)}` : label;
      fig.append(img, cap);
      row.appendChild(fig);
    }
    strip.appendChild(row);
  }
  document.body.dataset.views = report.test_views.length;
}

function fillMasks(sc) {
  const grid = $('mask-grid');
  grid.innerHTML = '';
  for (const im of sc.images) {
    if (im.split === 'excluded') continue;
    const stem = stemOf(im);
    const div = document.createElement('div');
    div.className = 'masked';
    const photo = document.createElement('img');
    photo.src = fileUrl(im.path);
    photo.loading = 'lazy';
    const mask = document.createElement('img');
    mask.className = 'overlay';
    mask.src = fileUrl(`masks/binary/${stem}.png`);
    mask.loading = 'lazy';
    mask.onerror = () => mask.remove();
    const name = document.createElement('span');
    name.textContent = im.name;
    div.append(photo, mask, name);
    grid.appendChild(div);
  }
}

function fillStages(run) {
  const body = $('stages').querySelector('tbody');
  body.innerHTML = '';
  if (!run || !run.stages) return;
  for (const s of run.stages) {
    const tr = document.createElement('tr');
    tr.innerHTML = `<td></td><td>${s.skipped ? 'skipped' : fmt(s.seconds, 1) + ' s'}</td><td></td>`;
    tr.children[0].textContent = s.stage;
    tr.children[2].textContent = s.reason || '';
    body.appendChild(tr);
  }
}

// The training PSNR of every iteration against the solve's time, a colour per level.
const curve = { offset: 0, points: [], last: null, busy: false };
function drawCurve() {
  const c = $('psnr-curve'), g = c.getContext('2d');
  g.fillStyle = '#1e2128';
  g.fillRect(0, 0, c.width, c.height);
  const pts = curve.points;
  if (!pts.length) {
    g.fillStyle = '#9aa0a6';
    g.fillText('no iterations logged yet', 12, 20);
    return;
  }
  const tmax = Math.max(...pts.map((p) => p.t)) || 1;
  const ymin = Math.floor(Math.min(...pts.map((p) => p.psnr))), ymax = Math.ceil(Math.max(...pts.map((p) => p.psnr)));
  const x = (t) => 40 + (c.width - 50) * t / tmax, y = (v) => c.height - 20 - (c.height - 30) * (v - ymin) / Math.max(1, ymax - ymin);
  g.strokeStyle = '#495057';
  g.strokeRect(40, 10, c.width - 50, c.height - 30);
  g.fillStyle = '#9aa0a6';
  g.fillText(`${ymax} dB`, 2, 14);
  g.fillText(`${ymin} dB`, 2, c.height - 20);
  g.fillText(`${tmax.toFixed(0)} s`, c.width - 40, c.height - 6);
  for (const p of pts) {
    g.fillStyle = LEVEL_COLOURS[p.level % LEVEL_COLOURS.length];
    g.fillRect(x(p.t) - 2, y(p.psnr) - 2, 4, 4);
  }
}

async function pollLog() {
  if (curve.busy) return;
  curve.busy = true;
  try {
    const r = await fetch(`/api/log?from=${curve.offset}`, { cache: 'no-store' });
    if (r.ok) {
      curve.offset = Number(r.headers.get('X-Next-Offset') || curve.offset);
      let base = curve.points.length ? curve.points[curve.points.length - 1].base : 0;
      for (const line of (await r.text()).split('\n')) {
        if (!line) continue;
        let e;
        try { e = JSON.parse(line); } catch (err) { continue; }
        if (e.event !== 'iteration') continue;
        // elapsed restarts with each level: the curve keeps a running total.
        if (curve.last && e.level !== curve.last.level) base = curve.last.t;
        const p = { t: base + e.elapsed, psnr: e.train_psnr, level: e.level, iteration: e.iteration, base };
        curve.points.push(p);
        curve.last = p;
      }
      if (curve.last) {
        $('progress').textContent = `${curve.points.length} iterations logged; last: level ${curve.last.level + 1}, ` +
          `iteration ${curve.last.iteration + 1}, ${fmt(curve.last.psnr, 2)} dB`;
        document.body.dataset.iterations = curve.points.length;
      }
      drawCurve();
    }
  } finally {
    curve.busy = false;
  }
}

// A running command's page (perf run --view): its state every 2 s, and the newest preview.
const live = { started: false, state: '' };
function describe(s) {
  const eta = s.eta_seconds >= 0 ? `, this level's ETA ${s.eta_seconds < 90 ? Math.round(s.eta_seconds) + ' s'
                                                                            : Math.round(s.eta_seconds / 60) + ' min'}` : '';
  if (s.state === 'stopped') return 'stopped (Ctrl-C): run the same command again to resume';
  if (s.state === 'finished') return 'finished; the server stays up until Ctrl-C';
  if (s.stage === 'reconstruct' && s.levels > 0) {
    return `reconstruct: level ${s.level + 1}/${s.levels}, iteration ${s.iteration}/${s.iterations}${eta}`;
  }
  return s.stage ? `${s.stage}...` : 'starting';
}
async function pollStatus() {
  const s = await getJson('/api/status');
  if (!s) {
    $('live-status').textContent = 'the run\'s server is gone (the run ended)';
    return;
  }
  $('live-status').textContent = describe(s);
  $('live-status').className = s.state === 'stopped' ? 'stopped' : '';
  $('status').textContent = s.state === 'running' ? 'solving' : s.state;
  document.body.dataset.state = s.state;
  document.body.dataset.liveIteration = s.iteration;
  if (s.preview && $('preview').dataset.src !== s.preview) {
    $('preview').dataset.src = s.preview;
    $('preview').src = fileUrl(s.preview);
  }
  if (s.state !== live.state && (s.state === 'finished' || s.state === 'stopped')) {
    const [sc, report, run] = await Promise.all([getJson('/api/scene'), getJson('/api/report'), getJson('/api/run')]);
    if (sc) fillScores(sc, report);
    fillStages(run);
  }
  live.state = s.state;
}
function startLive() {
  if (live.started) return;
  live.started = true;
  $('live').hidden = false;
  pollStatus();
  setInterval(pollStatus, 2000);
}

async function main() {
  const [sc, report, run, points, status] = await Promise.all(
    [getJson('/api/scene'), getJson('/api/report'), getJson('/api/run'), getJson('/api/points'), getJson('/api/status')]);
  if (status && status.live) startLive();
  if (!sc) {
    if (status && status.live) {  // the import has not written it yet
      $('status').textContent = 'waiting for the import...';
      setTimeout(main, 2000);
      return;
    }
    $('status').textContent = 'scene.json could not be read';
    $('status').className = 'error';
    document.body.dataset.ready = '1';
    return;
  }
  $('workspace').textContent = status ? status.workspace : '';
  $('status').textContent = status && status.live ? 'solving' : 'finished run';
  fillScores(sc, report);
  fillMasks(sc);
  fillStages(run);
  await pollLog();
  setInterval(pollLog, 2000);
  const meshDone = (state) => {
    document.body.dataset.mesh = state;
    // Two frames after the mesh is in, the canvas shows it.
    requestAnimationFrame(() => requestAnimationFrame(() => { document.body.dataset.ready = '1'; }));
  };
  if (!window.THREE || !THREE.OrbitControls || !THREE.GLTFLoader) {
    $('status').textContent = 'three.js is missing on the server (Debian libjs-three; scripts/setup.sh installs it)';
    $('status').className = 'error';
    document.body.dataset.ready = '1';
    return;
  }
  try {
    const view3 = startViewer(sc, points, meshDone);
    if (typeof PerfFieldView !== 'undefined') PerfFieldView.start(sc, view3.camera, view3.controls, fileUrl);
  } catch (e) {
    $('status').textContent = `the 3-D view failed: ${e.message}`;
    $('status').className = 'error';
    document.body.dataset.mesh = 'failed';
    document.body.dataset.ready = '1';
  }
}

main();
