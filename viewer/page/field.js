// The fitted radiance field in perf view's page: a WebGL2 ray marcher over /api/field's volume
// (viewer/field_payload.h, docs/viewer_field.md), drawn from any viewpoint. Its march is the one
// of recon_cuda/core (ray_march.h, grid_sample.h, shells.h, ray_math.h Forward and RulePixel),
// mirrored line by line in FIELD_SHADER below: a change to either that the other does not get
// fails view_page_test's comparison with perf render. No exposure: the volume's own colour.
// Loaded before view.js, which drives it (PerfField).
'use strict';

const PerfField = (() => {
  const MAGIC = 'PERFFLD';
  const VERSION = 1, HEADER = 256, MAX_SHELLS = 8;

  // /api/field's bytes as typed views, every count and size checked before anything is
  // allocated from them; throws an Error saying what is wrong.
  function parse(buffer) {
    const bytes = new Uint8Array(buffer);
    if (bytes.length < HEADER) throw new Error(`the volume is ${bytes.length} bytes, shorter than its header`);
    if (String.fromCharCode(...bytes.subarray(0, 7)) !== MAGIC || bytes[7] !== 0) throw new Error('not a PERF volume');
    const dv = new DataView(buffer);
    const version = dv.getUint32(8, true);
    if (version !== VERSION) throw new Error(`volume format version ${version}; this page reads ${VERSION}`);
    if (dv.getUint32(12, true) !== HEADER) throw new Error('unexpected header size');
    const i32 = (k) => dv.getInt32(16 + 4 * k, true);
    const f = { level: i32(0), iteration: i32(1), n: i32(2), m: i32(3), shells: i32(4), sh_degree: i32(5),
                bricks: i32(6), atlas: [i32(7), i32(8), i32(9)] };
    const f32 = (k) => dv.getFloat32(56 + 4 * k, true);
    f.box_center = [f32(0), f32(1), f32(2)];
    f.world_from_box = Array.from({ length: 9 }, (_, k) => f32(3 + k));
    f.box_size = [f32(12), f32(13), f32(14)];
    f.shell_center = [f32(15), f32(16), f32(17)];
    f.shell_radii = Array.from({ length: MAX_SHELLS }, (_, k) => f32(18 + k));
    const sizes = [0, 1, 2, 3].map((k) => Number(dv.getBigUint64(160 + 8 * k, true)));
    f.stop = dv.getFloat32(192, true);
    // The counts the sizes must match, before trusting either.
    const ok = (v, lo, hi) => Number.isInteger(v) && v >= lo && v <= hi;
    if (!ok(f.n, 1, 2048) || !ok(f.m, 1, 4096) || !ok(f.shells, 1, MAX_SHELLS) || !ok(f.sh_degree, 0, 2) ||
        !(f.stop >= 0 && f.stop < 1)) {
      throw new Error(`implausible volume (n ${f.n}, m ${f.m}, ${f.shells} shells, degree ${f.sh_degree})`);
    }
    const sparse = f.bricks >= 0;
    if (sparse && (f.n % 8 !== 0 || !ok(f.bricks, 0, (f.n / 8) ** 3) || f.atlas[0] * f.atlas[1] * f.atlas[2] < f.bricks)) {
      throw new Error(`implausible brick counts (n ${f.n}, ${f.bricks} bricks, atlas ${f.atlas})`);
    }
    const cells = sparse ? 512 * f.bricks : f.n ** 3;
    const stride = f.sh_degree > 0 ? Math.ceil((3 * ((f.sh_degree + 1) ** 2 - 1) + 3) / 4) * 4 : 0;
    const want = [sparse ? 4 * (f.n / 8) ** 3 : 0, 8 * cells, 2 * stride * cells, 2 * 4 * f.shells * 6 * f.m * f.m];
    for (let k = 0; k < 4; ++k) {
      if (sizes[k] !== want[k]) throw new Error(`section ${k} is ${sizes[k]} bytes where ${want[k]} are due`);
    }
    const total = HEADER + want.reduce((a, b) => a + b, 0);
    if (bytes.length !== total) throw new Error(`the volume is ${bytes.length} bytes where ${total} are due (cut short?)`);
    let at = HEADER;
    const take = (n, Type) => { const v = new Type(buffer, at, n / Type.BYTES_PER_ELEMENT); at += n; return v; };
    f.sparse = sparse;
    f.cells = cells;
    f.stride = stride;
    f.slots = sparse ? take(want[0], Int32Array) : null;
    f.grid = take(want[1], Uint16Array);
    f.bands = take(want[2], Uint16Array);
    f.shell_texels = take(want[3], Uint16Array);
    return f;
  }

  const VERTEX_SHADER = `#version 300 es
in vec2 p;
void main() { gl_Position = vec4(p, 0.0, 1.0); }`;

  // The march of one pixel: recon_cuda/core's code for rendering (no jitter, u = 0.5), in float.
  const FIELD_SHADER = `#version 300 es
precision highp float;
precision highp int;
precision highp sampler3D;
precision highp isampler3D;
precision highp sampler2DArray;
uniform sampler3D u_grid;        // (r, g, b, sigma) of a cell: the dense grid, or the bricks' atlas
uniform isampler3D u_slots;      // sparse: the brick table, (n / 8)^3
uniform sampler3D u_bands;       // spherical harmonics: stride / 4 slices of the grid's layout along z
uniform sampler2DArray u_shells; // (r, g, b, a) of a texel: m x m x (6 shells)
uniform int u_n, u_m, u_num_shells, u_sparse, u_sh_degree, u_slice_depth;
uniform ivec3 u_atlas;
uniform vec3 u_box_center, u_box_size, u_shell_center;
uniform mat3 u_box_rt;           // R^T of world_from_box (GLSL's mat3 is column-major: rows of R)
uniform float u_shell_radii[8];
uniform float u_stop, u_min_box_opacity;
uniform vec4 u_intrinsics;       // fx, fy, cx, cy of the drawing buffer's pixels
uniform mat3 u_cam_r;            // world_from_cam rotation (as R: column j is R's column j)
uniform vec3 u_cam_pos;
uniform float u_height;          // drawing buffer height (pixel rows are counted from the top)
out vec4 colour;

// ray_types.h LinearCoord: lo, hi and the weight of hi along one axis of n samples.
void LinearCoord(float s, int n, out int lo, out int hi, out float f) {
  float c = clamp(s - 0.5, 0.0, float(n - 1));
  int i = int(c);
  i = i < 0 ? 0 : (i > n - 1 ? n - 1 : i);
  lo = i;
  hi = i + 1 < n ? i + 1 : n - 1;
  f = c - float(i);
}

// A stored cell's texel, or false (an inactive brick's cell: ray_types.h SparseCell).
bool CellTexel(ivec3 c, out ivec3 texel) {
  if (u_sparse == 0) { texel = c; return true; }
  int slot = texelFetch(u_slots, c >> 3, 0).r;
  if (slot < 0) return false;
  ivec3 b = ivec3(slot % u_atlas.x, (slot / u_atlas.x) % u_atlas.y, slot / (u_atlas.x * u_atlas.y));
  texel = b * 8 + (c & 7);
  return true;
}

// grid_sample.h TrilinearWeights and GatherGrid, with ray_math.h AddShColour: (r, g, b, sigma).
vec4 Gather(vec3 g, vec3 y, bool bands) {
  int lo[3], hi[3];
  float f[3];
  for (int a = 0; a < 3; ++a) LinearCoord(g[a], u_n, lo[a], hi[a], f[a]);
  vec4 v = vec4(0.0);
  vec3 sh = vec3(0.0);
  for (int c = 0; c < 8; ++c) {
    ivec3 cell = ivec3((c & 1) != 0 ? hi[0] : lo[0], (c & 2) != 0 ? hi[1] : lo[1], (c & 4) != 0 ? hi[2] : lo[2]);
    float w = ((c & 1) != 0 ? f[0] : 1.0 - f[0]) * ((c & 2) != 0 ? f[1] : 1.0 - f[1]) * ((c & 4) != 0 ? f[2] : 1.0 - f[2]);
    ivec3 t;
    if (!CellTexel(cell, t)) continue;
    v += w * texelFetch(u_grid, t, 0);
    if (bands) {
      // band k, channel ch at 3 k + ch of the cell's stride (ray_types.h ShParam)
      vec4 b0 = texelFetch(u_bands, t, 0), b1 = texelFetch(u_bands, t + ivec3(0, 0, u_slice_depth), 0);
      vec4 b2 = texelFetch(u_bands, t + ivec3(0, 0, 2 * u_slice_depth), 0);
      sh += w * (y.x * vec3(b0.x, b0.y, b0.z) + y.y * vec3(b0.w, b1.x, b1.y) + y.z * vec3(b1.z, b1.w, b2.x));
    }
  }
  v.rgb += sh;
  return v;
}

// shells.h DirectionToCube: the face and (u, v) in [0, 1].
void DirectionToCube(vec3 d, out int face, out vec2 uv) {
  float ax = abs(d.x), ay = abs(d.y), az = abs(d.z), sc, tc, ma;
  if (ax >= ay && ax >= az) {
    face = d.x >= 0.0 ? 0 : 1; ma = ax; sc = d.x >= 0.0 ? -d.z : d.z; tc = -d.y;
  } else if (ay >= az) {
    face = d.y >= 0.0 ? 2 : 3; ma = ay; sc = d.x; tc = d.y >= 0.0 ? d.z : -d.z;
  } else {
    face = d.z >= 0.0 ? 4 : 5; ma = az; sc = d.z >= 0.0 ? d.x : -d.x; tc = -d.y;
  }
  uv = vec2((sc / ma + 1.0) * 0.5, (tc / ma + 1.0) * 0.5);
}

// shells.h TexelWeights and GatherTexels on shell k.
vec4 GatherShell(int k, int face, vec2 uv) {
  int ulo, uhi, vlo, vhi;
  float fu, fv;
  LinearCoord(uv.x * float(u_m), u_m, ulo, uhi, fu);
  LinearCoord(uv.y * float(u_m), u_m, vlo, vhi, fv);
  int layer = k * 6 + face;
  return (1.0 - fu) * (1.0 - fv) * texelFetch(u_shells, ivec3(ulo, vlo, layer), 0) +
         fu * (1.0 - fv) * texelFetch(u_shells, ivec3(uhi, vlo, layer), 0) +
         (1.0 - fu) * fv * texelFetch(u_shells, ivec3(ulo, vhi, layer), 0) +
         fu * fv * texelFetch(u_shells, ivec3(uhi, vhi, layer), 0);
}

void main() {
  // ray_march.h PixelRay through the pixel's centre, ToBoxRay, SetGridRay.
  float px = floor(gl_FragCoord.x), py = u_height - 1.0 - floor(gl_FragCoord.y);
  vec3 dc = vec3((px + 0.5 - u_intrinsics.z) / u_intrinsics.x, (py + 0.5 - u_intrinsics.w) / u_intrinsics.y, 1.0);
  vec3 wd = u_cam_r * dc;
  wd = wd * (1.0 / sqrt(dot(wd, wd)));
  vec3 o = u_box_rt * (u_cam_pos - u_box_center);
  vec3 d = u_box_rt * (wd * (1.0 / sqrt(dot(wd, wd))));
  float nf = float(u_n);
  vec3 scale = vec3(nf) / u_box_size;
  vec3 go = (o + u_box_size * 0.5) * scale, gd = d * scale;
  // SlabTest against [0, n]^3.
  float t0 = 0.0, t1 = 3.0e38;
  bool hit = true;
  for (int a = 0; a < 3; ++a) {
    if (gd[a] == 0.0) {
      if (go[a] < 0.0 || go[a] > nf) hit = false;
      continue;
    }
    float ta = (0.0 - go[a]) / gd[a], tb = (nf - go[a]) / gd[a];
    if (ta > tb) { float s = ta; ta = tb; tb = s; }
    t0 = max(t0, ta);
    t1 = min(t1, tb);
  }
  hit = hit && t1 > t0;
  float delta = min(u_box_size.x, min(u_box_size.y, u_box_size.z)) / nf;
  int count = hit ? int(ceil((t1 - t0) / delta)) : 0;
  // ray_types.h ShBasis (degree 1: the bands beyond the constant) at the box-frame direction.
  const float c1 = 0.4886025119029199;
  vec3 y = vec3(-c1 * d.y, c1 * d.z, -c1 * d.x);
  bool bands = u_sh_degree > 0;
  // ray_math.h Forward: front to back, ending once the transmittance is below stop.
  vec3 h = vec3(0.0);
  float depth = 0.0, trans = 1.0;
  for (int k = 0; k < count; ++k) {
    float start = t0 + float(k) * delta;
    float len = max(0.0, min(delta, t1 - start));
    float t = start + 0.5 * len;
    vec4 v = Gather(go + gd * t, y, bands);
    float od = v.a * len;
    float keep = exp(-od);
    float weight = trans * (1.0 - keep);
    h += weight * v.rgb;
    depth += od;
    trans *= keep;
    if (trans < u_stop) break;
  }
  float t_box = exp(-depth);
  // ray_math.h EvalShells: from the box exit (or the origin when the ray misses the box) outwards.
  float t_start = hit ? t1 : 0.0, p = 1.0;
  vec3 s = vec3(0.0);
  for (int k = 0; k < 8; ++k) {
    if (k >= u_num_shells) break;
    vec3 oc = o - u_shell_center;
    float b = dot(oc, d), r = u_shell_radii[k];
    float disc = b * b - (dot(oc, oc) - r * r);
    if (disc < 0.0) continue;
    float te = -b + sqrt(disc);
    if (!(te > t_start)) continue;
    int face;
    vec2 uv;
    DirectionToCube(o + d * te - u_shell_center, face, uv);
    vec4 e = GatherShell(k, face, uv);
    float a = k == u_num_shells - 1 ? 1.0 : e.a;
    s += p * a * e.rgb;
    p *= 1.0 - a;
  }
  h += t_box * s;
  // training_ray.h RulePixel: where the box's opacity is below the rule's threshold, the shells.
  colour = vec4(1.0 - t_box < u_min_box_opacity ? s : h, 1.0);
}`;

  function compile(gl, type, source) {
    const s = gl.createShader(type);
    gl.shaderSource(s, source);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error('field shader: ' + gl.getShaderInfoLog(s));
    return s;
  }

  // A renderer on `canvas` (its own WebGL2 context): load(volume) uploads a parsed volume;
  // draw(view, rule) marches every pixel of the drawing buffer for view = {fx, fy, cx, cy,
  // rotation: 3x3 rows of world_from_cam, position: [x, y, z]} under the render rule's threshold
  // `rule` (0: off) and returns the milliseconds it took.
  function Renderer(canvas) {
    const gl = canvas.getContext('webgl2', { preserveDrawingBuffer: true, antialias: false, alpha: false });
    if (!gl) throw new Error('this browser has no WebGL2');
    const program = gl.createProgram();
    gl.attachShader(program, compile(gl, gl.VERTEX_SHADER, VERTEX_SHADER));
    gl.attachShader(program, compile(gl, gl.FRAGMENT_SHADER, FIELD_SHADER));
    gl.linkProgram(program);
    if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error('field shader: ' + gl.getProgramInfoLog(program));
    const quad = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, quad);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-1, -1, 1, -1, -1, 1, 1, 1]), gl.STATIC_DRAW);
    const loc = (name) => gl.getUniformLocation(program, name);
    const textures = {};
    let volume = null;
    const max3d = gl.getParameter(gl.MAX_3D_TEXTURE_SIZE), maxLayers = gl.getParameter(gl.MAX_ARRAY_TEXTURE_LAYERS);

    function texture(name, target, unit) {
      if (textures[name]) gl.deleteTexture(textures[name]);
      const t = gl.createTexture();
      gl.activeTexture(gl.TEXTURE0 + unit);
      gl.bindTexture(target, t);
      for (const p of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(target, p, gl.NEAREST);
      textures[name] = t;
      return t;
    }
    function checkSize(what, w, h, d, limit) {
      if (w > max3d || h > max3d || d > limit) throw new Error(`${what} (${w} x ${h} x ${d}) is larger than this browser's textures`);
    }

    function load(f) {
      gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
      // The grid: dense as it is; sparse bricks into an atlas, brick slot s at atlas brick
      // (s % ax, s / ax % ay, s / (ax ay)).
      const dims = f.sparse ? f.atlas.map((a) => 8 * a) : [f.n, f.n, f.n];
      const slices = f.stride / 4;
      checkSize('the grid', dims[0], dims[1], dims[2] * Math.max(1, slices), max3d);
      texture('grid', gl.TEXTURE_3D, 0);
      gl.texImage3D(gl.TEXTURE_3D, 0, gl.RGBA16F, dims[0], dims[1], dims[2], 0, gl.RGBA, gl.HALF_FLOAT, f.sparse ? null : f.grid);
      const brickOrigin = (s) => [8 * (s % f.atlas[0]), 8 * (Math.floor(s / f.atlas[0]) % f.atlas[1]),
                                  8 * Math.floor(s / (f.atlas[0] * f.atlas[1]))];
      if (f.sparse) {
        for (let s = 0; s < f.bricks; ++s) {
          const [x, y, z] = brickOrigin(s);
          gl.texSubImage3D(gl.TEXTURE_3D, 0, x, y, z, 8, 8, 8, gl.RGBA, gl.HALF_FLOAT, f.grid.subarray(2048 * s, 2048 * (s + 1)));
        }
      }
      // The bands: slice q holds values 4q .. 4q + 3 of each cell's stride, slice after slice along z.
      texture('bands', gl.TEXTURE_3D, 2);
      if (slices > 0) {
        gl.texImage3D(gl.TEXTURE_3D, 0, gl.RGBA16F, dims[0], dims[1], dims[2] * slices, 0, gl.RGBA, gl.HALF_FLOAT, null);
        const block = f.sparse ? 512 : f.n * f.n;  // cells a brick, or a z-plane of the dense grid
        const part = new Uint16Array(4 * block);
        const blocks = f.sparse ? f.bricks : f.n;
        for (let q = 0; q < slices; ++q) {
          for (let b = 0; b < blocks; ++b) {
            for (let c = 0; c < block; ++c) {
              for (let v = 0; v < 4; ++v) part[4 * c + v] = f.bands[(b * block + c) * f.stride + 4 * q + v];
            }
            if (f.sparse) {
              const [x, y, z] = brickOrigin(b);
              gl.texSubImage3D(gl.TEXTURE_3D, 0, x, y, z + q * dims[2], 8, 8, 8, gl.RGBA, gl.HALF_FLOAT, part);
            } else {
              gl.texSubImage3D(gl.TEXTURE_3D, 0, 0, 0, b + q * dims[2], f.n, f.n, 1, gl.RGBA, gl.HALF_FLOAT, part);
            }
          }
        }
      } else {
        gl.texImage3D(gl.TEXTURE_3D, 0, gl.RGBA16F, 1, 1, 1, 0, gl.RGBA, gl.HALF_FLOAT, new Uint16Array(4));
      }
      texture('slots', gl.TEXTURE_3D, 1);
      const nb = f.sparse ? f.n / 8 : 1;
      gl.texImage3D(gl.TEXTURE_3D, 0, gl.R32I, nb, nb, nb, 0, gl.RED_INTEGER, gl.INT, f.sparse ? f.slots : new Int32Array(1));
      checkSize('the shells', f.m, f.m, 6 * f.shells, maxLayers);
      texture('shells', gl.TEXTURE_2D_ARRAY, 3);
      gl.texImage3D(gl.TEXTURE_2D_ARRAY, 0, gl.RGBA16F, f.m, f.m, 6 * f.shells, 0, gl.RGBA, gl.HALF_FLOAT, f.shell_texels);
      volume = Object.assign({ sliceDepth: dims[2] }, f);
      volume.grid = volume.bands = volume.shell_texels = volume.slots = null;  // uploaded: not kept
    }

    function draw(view, rule) {
      if (!volume) return 0;
      const f = volume;
      const t0 = performance.now();
      gl.viewport(0, 0, canvas.width, canvas.height);
      gl.useProgram(program);
      [['u_grid', 0], ['u_slots', 1], ['u_bands', 2], ['u_shells', 3]].forEach(([n, u]) => gl.uniform1i(loc(n), u));
      gl.uniform1i(loc('u_n'), f.n);
      gl.uniform1i(loc('u_m'), f.m);
      gl.uniform1i(loc('u_num_shells'), f.shells);
      gl.uniform1i(loc('u_sparse'), f.sparse ? 1 : 0);
      gl.uniform1i(loc('u_sh_degree'), f.sh_degree === 1 ? 1 : 0);  // degree 2's bands are not drawn
      gl.uniform1i(loc('u_slice_depth'), f.sliceDepth);
      gl.uniform3iv(loc('u_atlas'), f.sparse ? f.atlas : [1, 1, 1]);
      gl.uniform3fv(loc('u_box_center'), f.box_center);
      gl.uniform3fv(loc('u_box_size'), f.box_size);
      gl.uniform3fv(loc('u_shell_center'), f.shell_center);
      // R row-major: as a column-major mat3 it is R^T, which maps world to box.
      gl.uniformMatrix3fv(loc('u_box_rt'), false, f.world_from_box);
      gl.uniform1fv(loc('u_shell_radii'), f.shell_radii);
      gl.uniform1f(loc('u_stop'), f.stop);
      gl.uniform1f(loc('u_min_box_opacity'), rule);
      gl.uniform4f(loc('u_intrinsics'), view.fx, view.fy, view.cx, view.cy);
      const r = view.rotation;
      gl.uniformMatrix3fv(loc('u_cam_r'), true, [r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2]]);
      gl.uniform3fv(loc('u_cam_pos'), view.position);
      gl.uniform1f(loc('u_height'), canvas.height);
      const p = gl.getAttribLocation(program, 'p');
      gl.bindBuffer(gl.ARRAY_BUFFER, quad);
      gl.enableVertexAttribArray(p);
      gl.vertexAttribPointer(p, 2, gl.FLOAT, false, 0, 0);
      gl.drawArrays(gl.TRIANGLE_STRIP, 0, 4);
      const pixel = new Uint8Array(4);
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);  // waits for the frame: its time
      return performance.now() - t0;
    }
    // The drawing buffer's RGBA bytes, top row first.
    function pixels() {
      const w = canvas.width, h = canvas.height, out = new Uint8Array(4 * w * h), row = new Uint8Array(4 * w);
      gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, out);
      for (let y = 0; y < h / 2; ++y) {  // GL's rows start at the bottom
        const a = out.subarray(4 * w * y, 4 * w * (y + 1)), b = out.subarray(4 * w * (h - 1 - y), 4 * w * (h - y));
        row.set(a);
        a.set(b);
        b.set(row);
      }
      return out;
    }
    return { load, draw, pixels, loaded: () => volume };
  }

  return { parse, Renderer, FIELD_SHADER };
})();
