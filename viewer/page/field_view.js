// perf view's field panel (field.js draws): the fitted volume behind the 3-D view, seen through the
// orbit camera (flown with W A S D Q E, view.js) or snapped to any photo's camera with its intrinsics; the level to show (or the
// running solve's newest volume, polled every 3 s); the render rule; a slider from the render to
// the photo with their PSNR; the frame time. A coarse frame (a quarter of the pixels) while the
// view moves, the full one once it rests. URL options: ?field=<photo name> snaps to that photo,
// &level=<k>, &rule=<threshold>, &width=&height= (the free view's drawing buffer); &dump=1 then
// puts the drawn pixels into body[data-field-png]
// (view_page_test compares them with perf render's). Test hooks: body[data-field-ready],
// body[data-field-version], body[data-field-level], body[data-field-psnr], body[data-field-ms],
// body[data-field-error].
'use strict';

const PerfFieldView = (() => {
  const $ = (id) => document.getElementById(id);
  const params = new URLSearchParams(location.search);

  // scene.json's photo as a pinhole view at its own size: refined pose and focal where fitted.
  function photoView(sc, im) {
    const cam = sc.cameras.find((c) => c.id === im.camera_id);
    const pose = im.refined_world_from_cam || im.world_from_cam;
    const s = im.refined_world_from_cam && im.refined_focal_scale ? im.refined_focal_scale : 1;
    return { fx: cam.fx * s, fy: cam.fy * s, cx: cam.cx, cy: cam.cy, width: cam.width, height: cam.height,
             rotation: [0, 1, 2].map((i) => [pose[i][0], pose[i][1], pose[i][2]]),
             position: [pose[0][3], pose[1][3], pose[2][3]] };
  }

  // The orbit camera (three.js: looking down -z, y up) as a pinhole view (x right, y down, z
  // forward) of a width x height drawing buffer.
  function orbitView(camera3, width, height) {
    camera3.updateMatrixWorld();
    const e = camera3.matrixWorld.elements;  // column-major: right, up, back, position
    const fy = 0.5 * height / Math.tan(camera3.fov * Math.PI / 360);
    return { fx: fy, fy, cx: 0.5 * width, cy: 0.5 * height, width, height,
             rotation: [0, 1, 2].map((i) => [e[i], -e[4 + i], -e[8 + i]]), position: [e[12], e[13], e[14]] };
  }

  // Fly controls: the move of one key press in world units, along the camera's own axes (right,
  // up, back: three.js's columns of its world matrix) by `step`: W / S forward and back, A / D
  // left and right, E / Q up and down; null for any other key. The orbit target moves with the
  // camera (view.js), so the mouse then turns around the point as far ahead as before.
  function flyMove(key, right, up, back, step) {
    const axes = { w: [back, -1], s: [back, 1], a: [right, -1], d: [right, 1], e: [up, 1], q: [up, -1] };
    const a = axes[String(key).toLowerCase()];
    return a ? a[0].map((v) => v * a[1] * step) : null;
  }

  function psnr(a, b) {  // RGBA bytes of two images of one size, over RGB
    let sse = 0, n = 0;
    for (let i = 0; i < a.length; i += 4) {
      for (let c = 0; c < 3; ++c) { const d = (a[i + c] - b[i + c]) / 255; sse += d * d; ++n; }
    }
    return sse > 0 ? -10 * Math.log10(sse / n) : 99;
  }

  function start(sc, camera3, controls, fileUrl) {
    const canvas = $('field3d'), info = $('field-info'), body = document.body;
    let renderer;
    try {
      renderer = PerfField.Renderer(canvas);
    } catch (e) {
      info.textContent = `the field is not drawn: ${e.message}`;
      body.dataset.fieldError = e.message;
      body.dataset.fieldReady = '1';
      return;
    }
    const state = { shown: null, version: -1, snapped: null, rule: Number(params.get('rule') || 0), timer: 0 };
    const levelSelect = $('field-level'), cameraSelect = $('field-camera'), ruleBox = $('field-rule');
    const slider = $('field-photo'), photo = $('field-photo-img');
    ruleBox.checked = state.rule > 0;
    for (const im of sc.images) {
      const o = document.createElement('option');
      o.value = im.name;
      o.textContent = `${im.name} (${im.split})`;
      cameraSelect.appendChild(o);
    }

    function draw(coarse) {
      if (!renderer.loaded() || !$('field-on').checked) return;
      let view;
      if (state.snapped) {
        view = photoView(sc, state.snapped);
        canvas.width = view.width;
        canvas.height = view.height;
      } else {
        // ?width=&height=: a drawing buffer of that size (CSS-scaled), e.g. to time 640 x 480.
        const w = Number(params.get('width')) || Math.max(1, canvas.clientWidth);
        const h = Number(params.get('height')) || Math.max(1, canvas.clientHeight), k = coarse ? 4 : 1;
        canvas.width = Math.ceil(w / k);
        canvas.height = Math.ceil(h / k);
        view = orbitView(camera3, canvas.width, canvas.height);
      }
      const ms = renderer.draw(view, state.rule);
      info.textContent = `level ${state.shown.level + 1}${state.shown.iteration >= 0 ? `, iteration ${state.shown.iteration + 1}` : ''}` +
        `: ${canvas.width} x ${canvas.height} in ${ms.toFixed(0)} ms${coarse ? ' (coarse while moving)' : ''}`;
      body.dataset.fieldMs = ms.toFixed(1);
      if (state.snapped && !coarse) comparePhoto();
    }
    function comparePhoto() {
      const im = state.snapped, img = new Image();
      img.onload = () => {
        const c = document.createElement('canvas');
        c.width = canvas.width;
        c.height = canvas.height;
        const g = c.getContext('2d');
        g.drawImage(img, 0, 0, c.width, c.height);
        const p = psnr(renderer.pixels(), g.getImageData(0, 0, c.width, c.height).data);
        body.dataset.fieldPsnr = p.toFixed(2);
        info.textContent += `; ${p.toFixed(2)} dB against the photo`;
        if (params.get('dump') === '1') body.dataset.fieldPng = canvas.toDataURL('image/png');
        body.dataset.fieldReady = '1';
      };
      img.onerror = () => { body.dataset.fieldReady = '1'; };
      img.src = fileUrl(im.path);
    }
    const redraw = () => {  // coarse now, the full frame once the view rests
      draw(true);
      clearTimeout(state.timer);
      state.timer = setTimeout(() => draw(false), 250);
    };
    // Moving the orbit camera by hand (its 'start') leaves the photo's view; its changes redraw.
    controls.addEventListener('start', () => {
      if (!state.snapped) return;
      state.snapped = null;
      cameraSelect.value = '';
      photo.hidden = true;
    });
    controls.addEventListener('change', () => { if (!state.snapped) redraw(); });
    window.addEventListener('resize', () => { if (!state.snapped) redraw(); });
    ruleBox.addEventListener('change', () => { state.rule = ruleBox.checked ? 0.7 : 0; draw(false); });
    $('field-on').addEventListener('change', () => {
      canvas.hidden = !$('field-on').checked;
      draw(false);
    });
    slider.addEventListener('input', () => { photo.style.opacity = slider.value / 100; });
    cameraSelect.addEventListener('change', () => snap(sc.images.find((im) => im.name === cameraSelect.value)));

    // Puts the orbit camera where the photo was taken and draws the photo's own view.
    function snap(im) {
      state.snapped = im || null;
      photo.hidden = !im;
      if (!im) return draw(false);
      const v = photoView(sc, im);
      const r = v.rotation;
      const pos = new THREE.Vector3(...v.position), forward = new THREE.Vector3(r[0][2], r[1][2], r[2][2]);
      camera3.position.copy(pos);
      camera3.up.set(-r[0][1], -r[1][1], -r[2][1]);
      camera3.fov = 2 * Math.atan(0.5 * v.height / v.fy) * 180 / Math.PI;
      camera3.updateProjectionMatrix();
      const target = pos.clone().add(forward.multiplyScalar(Math.max(1e-6, pos.distanceTo(controls.target))));
      camera3.lookAt(target);
      controls.target.copy(target);
      photo.src = fileUrl(im.path);
      photo.style.opacity = slider.value / 100;
      draw(false);
    }

    async function show(level) {  // level: a number, or 'live'
      const url = level === 'live' ? '/api/field' : `/api/field?level=${level}`;
      try {
        const r = await fetch(url, { cache: 'no-store' });
        if (!r.ok) throw new Error(`${url}: ${r.status}`);
        const f = PerfField.parse(await r.arrayBuffer());
        renderer.load(f);
        state.shown = { level: f.level, iteration: f.iteration };
        body.dataset.fieldLevel = f.level;
        body.dataset.fieldError = '';
      } catch (e) {
        info.textContent = `the volume could not be shown: ${e.message}`;
        body.dataset.fieldError = e.message;
        body.dataset.fieldReady = '1';
        return false;
      }
      draw(false);
      return true;
    }

    // The levels there are, and the running solve's newest volume: a new one is shown when the
    // choice is "newest".
    async function poll(first) {
      let list;
      try {
        const r = await fetch('/api/fields', { cache: 'no-store' });
        list = r.ok ? await r.json() : null;
      } catch (e) {
        list = null;
      }
      if (!list) return;
      const options = list.levels.map((l) => String(l.level));
      const have = Array.from(levelSelect.options).map((o) => o.value).filter((v) => v !== 'newest');
      if (options.join() !== have.join()) {
        const keep = levelSelect.value;
        levelSelect.innerHTML = '<option value="newest">newest</option>';
        for (const l of list.levels) {
          const o = document.createElement('option');
          o.value = String(l.level);
          o.textContent = `level ${l.level + 1}`;
          levelSelect.appendChild(o);
        }
        levelSelect.value = keep && Array.from(levelSelect.options).some((o) => o.value === keep) ? keep : 'newest';
      }
      if (first && params.get('level') !== null) levelSelect.value = params.get('level');
      if (levelSelect.value !== 'newest' && !first) return;
      const newest = levelSelect.value !== 'newest' ? Number(levelSelect.value) : list.newest;
      if (newest === null || newest === undefined) return;
      const version = newest === 'live' ? `live ${list.live.version}` : `level ${newest}`;
      if (version === state.version) return;
      if (await show(newest)) {
        state.version = version;
        body.dataset.fieldVersion = version;
      }
    }
    levelSelect.addEventListener('change', () => {
      state.version = -1;
      if (levelSelect.value === 'newest') poll(false);
      else show(Number(levelSelect.value)).then(() => { state.version = `level ${levelSelect.value}`; });
    });

    poll(true).then(() => {
      const name = params.get('field');
      if (name) {
        const im = sc.images.find((i) => i.name === name);
        if (!im) {
          body.dataset.fieldError = `no photo named ${name}`;
          body.dataset.fieldReady = '1';
          return;
        }
        cameraSelect.value = name;
        snap(im);
      } else {
        body.dataset.fieldReady = '1';
      }
    });
    setInterval(() => poll(false), 3000);
  }

  return { start, photoView, orbitView, flyMove };
})();
