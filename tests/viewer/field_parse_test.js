// perf view's reading of /api/field (viewer/page/field.js PerfField.parse, docs/viewer_field.md)
// under Node: a well-formed volume is read, and every malformed one (cut short, too long, another
// format or version, sections that do not match the counts, implausible counts) is refused with a
// message before anything is allocated from its counts. The page shows that message
// (field_view.js). Usage: node field_parse_test.js viewer/page/field.js
'use strict';
const fs = require('fs');
const vm = require('vm');
const assert = require('assert');

const context = { performance: { now: () => 0 }, console };
vm.createContext(context);
vm.runInContext(fs.readFileSync(process.argv[2], 'utf8') + '\nthis.PerfField = PerfField;', context);
const { parse } = context.PerfField;

// A dense n^3 volume of `shells` shells of m x m texels, degree 0, its header as field_payload.cc
// writes it; `edit(view)` may change the header.
function volume(n, m, shells, edit) {
  const sections = [0, 8 * n ** 3, 0, 8 * shells * 6 * m * m];
  const total = 256 + sections.reduce((a, b) => a + b, 0);
  const buf = new ArrayBuffer(total), dv = new DataView(buf), bytes = new Uint8Array(buf);
  bytes.set([...'PERFFLD'].map((c) => c.charCodeAt(0)), 0);
  dv.setUint32(8, 1, true);
  dv.setUint32(12, 256, true);
  [0, -1, n, m, shells, 0, -1, 0, 0, 0].forEach((v, k) => dv.setInt32(16 + 4 * k, v, true));
  [0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 2, 2, 2, 0, 0, 0, 3, 6].forEach((v, k) => dv.setFloat32(56 + 4 * k, v, true));
  sections.forEach((v, k) => dv.setBigUint64(160 + 8 * k, BigInt(v), true));
  dv.setFloat32(192, 1e-3, true);
  if (edit) edit(dv);
  return buf;
}

const ok = parse(volume(4, 2, 2));
assert.strictEqual(ok.n, 4);
assert.strictEqual(ok.sparse, false);
assert.strictEqual(ok.grid.length, 4 * 64);
assert.strictEqual(ok.shell_texels.length, 4 * 2 * 6 * 4);
assert.ok(Math.abs(ok.stop - 1e-3) < 1e-9);

function refused(buf, words) {
  assert.throws(() => parse(buf), (e) => {
    assert.ok(e.message.includes(words), `"${e.message}" does not say "${words}"`);
    return true;
  });
}
const good = volume(4, 2, 2);
refused(good.slice(0, good.byteLength - 1), 'cut short');
refused(good.slice(0, 100), 'shorter than its header');
const longer = new Uint8Array(good.byteLength + 8);
longer.set(new Uint8Array(good));
refused(longer.buffer, 'cut short');  // more bytes than due: refused as well
refused(volume(4, 2, 2, (dv) => dv.setUint8(0, 0x51)), 'not a PERF volume');
refused(volume(4, 2, 2, (dv) => dv.setUint32(8, 2, true)), 'version 2');
refused(volume(4, 2, 2, (dv) => dv.setBigUint64(168, 16n, true)), 'section 1');
// Counts that would allocate gigabytes are refused before anything is allocated.
refused(volume(4, 2, 2, (dv) => dv.setInt32(24, 1 << 20, true)), 'implausible volume');
refused(volume(4, 2, 2, (dv) => dv.setInt32(32, 9, true)), 'implausible volume');
refused(volume(8, 2, 2, (dv) => dv.setInt32(40, 5, true)), 'implausible brick counts');  // 5 of 1 brick
console.log('field_parse_test: all cases passed');
