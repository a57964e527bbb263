// perf view's fly controls (viewer/page/field_view.js PerfFieldView.flyMove, wired in view.js):
// each key moves along the camera's own axis by the step, W towards where the camera looks, and
// any other key does nothing. Usage: node fly_test.js viewer/page/field_view.js
'use strict';
const fs = require('fs');
const vm = require('vm');
const assert = require('assert');

const context = { location: { search: '' }, URLSearchParams, document: {}, console };
vm.createContext(context);
vm.runInContext(fs.readFileSync(process.argv[2], 'utf8') + '\nthis.PerfFieldView = PerfFieldView;', context);
const { flyMove } = context.PerfFieldView;

// A camera at (0, 0, 10) looking at the origin, y up, as three.js's lookAt leaves it: right +x,
// up +y, back +z (it looks down -z).
const right = [1, 0, 0], up = [0, 1, 0], back = [0, 0, 1];
const close = (a, b) => a.every((v, k) => Math.abs(v - b[k]) < 1e-12);
const expect = { w: [0, 0, -0.5], s: [0, 0, 0.5], a: [-0.5, 0, 0], d: [0.5, 0, 0], e: [0, 0.5, 0], q: [0, -0.5, 0] };
for (const [key, move] of Object.entries(expect)) {
  assert.ok(close(Array.from(flyMove(key, right, up, back, 0.5)), move), `${key}: ${flyMove(key, right, up, back, 0.5)}`);
  assert.ok(close(Array.from(flyMove(key.toUpperCase(), right, up, back, 0.5)), move), `${key.toUpperCase()} (Shift)`);
}
// W brings a camera that looks at the origin closer to it.
const position = [0, 0, 10], w = flyMove('w', right, up, back, 1);
assert.ok(Math.hypot(...position.map((v, k) => v + w[k])) < 10, 'W moves towards where the camera looks');
// A turned camera: its axes, not the world's.
const r2 = [0, 0, -1], u2 = [0, 1, 0], b2 = [1, 0, 0];  // turned 90 degrees about y
assert.ok(close(Array.from(flyMove('w', r2, u2, b2, 2)), [-2, 0, 0]));
assert.ok(close(Array.from(flyMove('d', r2, u2, b2, 2)), [0, 0, -2]));
for (const key of ['x', 'ArrowUp', ' ', 'Enter', '']) assert.strictEqual(flyMove(key, right, up, back, 1), null, key);
console.log('fly_test: 6 keys along the camera axes, other keys ignored: ok');
