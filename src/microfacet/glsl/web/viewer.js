// microfacet WebGL2 viewer: a plane and a sphere carrying a LEADR-filtered displacement map,
// shaded by the package's GLSL (fetched from the local server as GLSL ES 3.00).
// No dependencies, no build step. The page exposes `window.mfViewer` for tests and
// benchmarks: renderPatch(), benchmark().

const F = 4;   // bytes per float

async function fetchOk(url, kind) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
  return kind === "json" ? r.json() : kind === "text" ? r.text() : r.arrayBuffer();
}

function mat4Multiply(a, b) {      // column-major
  const o = new Float32Array(16);
  for (let c = 0; c < 4; ++c) for (let r = 0; r < 4; ++r) {
    let s = 0;
    for (let k = 0; k < 4; ++k) s += a[k * 4 + r] * b[c * 4 + k];
    o[c * 4 + r] = s;
  }
  return o;
}

function perspective(fovy, aspect, near, far) {
  const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
  return new Float32Array([f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0]);
}

function lookAt(eye, target, up) {
  const sub = (a, b) => a.map((v, i) => v - b[i]);
  const norm = (a) => { const l = Math.hypot(...a); return a.map((v) => v / l); };
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const z = norm(sub(eye, target)), x = norm(cross(up, z)), y = cross(z, x);
  return new Float32Array([x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
                           -dot(x, eye), -dot(y, eye), -dot(z, eye), 1]);
}

function spherical(yaw, pitch, r, c) {
  return [c[0] + r * Math.cos(pitch) * Math.sin(yaw), c[1] + r * Math.sin(pitch), c[2] + r * Math.cos(pitch) * Math.cos(yaw)];
}

// Interleaved vertices: position (3), uv (2), tangent (3), normal (3).
function planeMesh(x0, x1, z0, z1) {
  // uv = (x, z + 1): u along world x, v along world z (local frame s = x, t = -z, n = y)
  const v = [];
  for (const [x, z] of [[x0, z0], [x1, z0], [x1, z1], [x0, z0], [x1, z1], [x0, z1]]) v.push(x, 0, z, x, z + 1, 1, 0, 0, 0, 1, 0);
  return new Float32Array(v);
}

function patchMesh() {   // the unit uv square: world (u, 0, v - 1), as microfacet.leadr.figures.PatchScene
  const v = [];
  for (const [u, w] of [[0, 0], [1, 0], [1, 1], [0, 0], [1, 1], [0, 1]]) v.push(u, 0, w - 1, u, w, 1, 0, 0, 0, 1, 0);
  return new Float32Array(v);
}

function sphereMesh(c, r, rings, segments, tiles) {
  const vert = (i, j) => {
    const th = (i / rings) * Math.PI, ph = (j / segments) * 2 * Math.PI;
    const n = [Math.sin(th) * Math.sin(ph), Math.cos(th), Math.sin(th) * Math.cos(ph)];
    const s = [Math.cos(ph), 0, -Math.sin(ph)];
    return [c[0] + r * n[0], c[1] + r * n[1], c[2] + r * n[2], tiles * 2 * j / segments, tiles * i / rings, ...s, ...n];
  };
  const v = [];
  for (let i = 0; i < rings; ++i) for (let j = 0; j < segments; ++j) {
    const a = vert(i, j), b = vert(i + 1, j), cc = vert(i + 1, j + 1), d = vert(i, j + 1);
    v.push(...a, ...b, ...cc, ...a, ...cc, ...d);
  }
  return new Float32Array(v);
}

export class Viewer {
  constructor(canvas) {
    this.canvas = canvas;
    this.state = { method: 1, light: 0, supersampling: 4, diffuse: false, exposure: 0,
                   yaw: 0.6, pitch: 0.5, distance: 3.2, lightYaw: -2.2, lightPitch: 0.8 };
    this.frameMs = NaN;
    this.ready = new Promise((resolve, reject) => { this._resolve = resolve; this._reject = reject; });
  }

  async start() {
    try {
      await this._init();
      this._bindUi();
      this._resolve(true);
      this._loop();
    } catch (e) {
      this._reject(e);
      throw e;
    }
  }

  async _init() {
    const gl = this.canvas.getContext("webgl2", { antialias: false, preserveDrawingBuffer: true });
    if (!gl) throw new Error("WebGL2 is not available");
    for (const ext of ["EXT_color_buffer_float", "OES_texture_float_linear"]) {
      if (!gl.getExtension(ext)) throw new Error(`WebGL2 extension ${ext} is missing`);
    }
    this.gl = gl;
    const [meta, leadr, naive, env, vs, fs] = await Promise.all([
      fetchOk("meta.json", "json"), fetchOk("leadr.bin"), fetchOk("naive.bin"), fetchOk("env.bin"),
      fetchOk("shader/viewer.vert", "text"), fetchOk("shader/viewer.frag", "text")]);
    this.meta = meta;
    document.getElementById("title").textContent = `${meta.name} (${meta.base})`;
    this.program = this._program(vs, fs);
    this.leadr = this._moments(leadr, meta.leadr);
    this.naive = this._moments(naive, meta.naive);
    this.env = this._levels(env, meta.env, 4, gl.RGBA32F, gl.RGBA, [gl.REPEAT, gl.CLAMP_TO_EDGE]);
    const table = new Float32Array(64 * 3 * 4);
    (meta.fresnel.table || []).forEach((row, j) => table.set(row, (2 * 64 + j) * 4));
    this.fitTable = this._levels(table.buffer, [[3, 64, 4]], 4, gl.RGBA32F, gl.RGBA, [gl.CLAMP_TO_EDGE, gl.CLAMP_TO_EDGE], true);
    this.meshes = {
      scene: [this._mesh(planeMesh(-2, 2, -2, 2)), this._mesh(sphereMesh([0, 0.55, 0], 0.55, 48, 96, 2))],
      patch: [this._mesh(patchMesh())],
    };
  }

  _program(vs, fs) {
    const gl = this.gl;
    const compile = (type, text) => {
      const s = gl.createShader(type);
      gl.shaderSource(s, text);
      gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(`shader: ${gl.getShaderInfoLog(s)}`);
      return s;
    };
    const p = gl.createProgram();
    gl.attachShader(p, compile(gl.VERTEX_SHADER, vs));
    gl.attachShader(p, compile(gl.FRAGMENT_SHADER, fs));
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(`program: ${gl.getProgramInfoLog(p)}`);
    return p;
  }

  // A float texture from levels stored one after the other in `buffer` (shapes [H, W, C]).
  _levels(buffer, shapes, channels, internal, format, wrap, nearest = false) {
    const gl = this.gl;
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, tex);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    let offset = 0;
    shapes.forEach(([h, w, c], k) => {
      if (c !== channels) throw new Error(`level ${k} has ${c} channels, expected ${channels}`);
      gl.texImage2D(gl.TEXTURE_2D, k, internal, w, h, 0, format, gl.FLOAT, new Float32Array(buffer, offset, h * w * c));
      offset += h * w * c * F;
    });
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAX_LEVEL, shapes.length - 1);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, nearest ? gl.NEAREST : gl.LINEAR_MIPMAP_NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, nearest ? gl.NEAREST : gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, wrap[0]);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, wrap[1]);
    return tex;
  }

  // Moment pyramid (H, W, 5) levels -> RGBA32F (E1..E4) + R32F (E5) textures.
  _moments(buffer, shapes) {
    const gl = this.gl;
    const all = new Float32Array(buffer);
    const a = [], b = [];
    let offset = 0, bytesA = 0, bytesB = 0;
    const partsA = [], partsB = [];
    for (const [h, w] of shapes) {
      const n = h * w, la = new Float32Array(4 * n), lb = new Float32Array(n);
      for (let i = 0; i < n; ++i) {
        for (let c = 0; c < 4; ++c) la[4 * i + c] = all[offset + 5 * i + c];
        lb[i] = all[offset + 5 * i + 4];
      }
      offset += 5 * n;
      partsA.push(la); partsB.push(lb);
      a.push([h, w, 4]); b.push([h, w, 1]);
      bytesA += la.byteLength; bytesB += lb.byteLength;
    }
    const join = (parts, bytes) => { const o = new Float32Array(bytes / F); let p = 0; for (const x of parts) { o.set(x, p); p += x.length; } return o.buffer; };
    return { a: this._levels(join(partsA, bytesA), a, 4, gl.RGBA32F, gl.RGBA, [gl.REPEAT, gl.REPEAT]),
             b: this._levels(join(partsB, bytesB), b, 1, gl.R32F, gl.RED, [gl.REPEAT, gl.REPEAT]),
             top: shapes.length - 1 };
  }

  _mesh(data) {
    const gl = this.gl;
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    const buf = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, buf);
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    let offset = 0;
    for (const [name, size] of [["a_position", 3], ["a_uv", 2], ["a_tangent", 3], ["a_normal", 3]]) {
      const loc = gl.getAttribLocation(this.program, name);
      if (loc >= 0) {
        gl.enableVertexAttribArray(loc);
        gl.vertexAttribPointer(loc, size, gl.FLOAT, false, 11 * F, offset * F);
      }
      offset += size;
    }
    gl.bindVertexArray(null);
    return { vao, count: data.length / 11 };
  }

  _uniforms(patch, eye, viewProjection, display) {
    const gl = this.gl, p = this.program, m = this.meta, s = this.state;
    const u = (name) => gl.getUniformLocation(p, name);
    gl.useProgram(p);
    gl.uniform1i(u("u_patch"), patch ? 1 : 0);
    gl.uniformMatrix4fv(u("u_view_projection"), false, viewProjection);
    gl.uniform1i(u("u_method"), s.method);
    gl.uniform1i(u("u_light_kind"), s.light);
    gl.uniform1i(u("u_supersampling"), s.supersampling);
    gl.uniform3fv(u("u_eye"), eye);
    gl.uniform3fv(u("u_light"), patch ? this.patchToWorld(m.light) : this.lightPosition());
    gl.uniform1f(u("u_intensity"), m.intensity);
    gl.uniform1i(u("u_fresnel.kind"), m.fresnel.kind);
    gl.uniform3fv(u("u_fresnel.a"), m.fresnel.a || [0, 0, 0]);
    gl.uniform3fv(u("u_fresnel.b"), m.fresnel.b || [0, 0, 0]);
    gl.uniform3i(u("mf_fit_sizes"), 0, 0, (m.fresnel.table || []).length);
    gl.uniform1i(u("u_leadr_top"), this.leadr.top);
    gl.uniform1i(u("u_naive_top"), this.naive.top);
    gl.uniform1i(u("u_env_top"), m.env.length - 1);
    gl.uniform1f(u("u_env_T"), m.env_T);
    gl.uniform1i(u("u_grid"), m.grid);
    gl.uniform3fv(u("u_sh"), new Float32Array(m.sh.flat()));
    gl.uniform3fv(u("u_albedo"), s.diffuse ? [0.5, 0.5, 0.5] : [0, 0, 0]);
    gl.uniform1i(u("u_display"), display ? 1 : 0);
    gl.uniform1f(u("u_exposure"), s.exposure);
    const units = [["u_leadr_a", this.leadr.a], ["u_leadr_b", this.leadr.b], ["u_naive_a", this.naive.a],
                   ["u_naive_b", this.naive.b], ["u_env", this.env], ["mf_fit_table", this.fitTable]];
    units.forEach(([name, tex], i) => {
      gl.activeTexture(gl.TEXTURE0 + i);
      gl.bindTexture(gl.TEXTURE_2D, tex);
      gl.uniform1i(u(name), i);
    });
  }

  patchToWorld(q) { return [q[0], q[2], -q[1]]; }     // PatchScene's local (x, y, z) -> world (x, z, -y)

  lightPosition() { return spherical(this.state.lightYaw, this.state.lightPitch, 2.5, [0, 0, 0]); }

  cameraPosition() { return spherical(this.state.yaw, this.state.pitch, this.state.distance, [0, 0.3, 0]); }

  // Draw the scene (or the patch) into the bound framebuffer of size w x h.
  draw(w, h, { patch = false, display = true } = {}) {
    const gl = this.gl;
    const eye = patch ? this.patchToWorld(this.meta.camera) : this.cameraPosition();
    const vp = mat4Multiply(perspective(0.8, w / h, 0.05, 50), lookAt(eye, [0, 0.3, 0], [0, 1, 0]));
    gl.viewport(0, 0, w, h);
    gl.enable(gl.DEPTH_TEST);
    gl.clearColor(0.1, 0.1, 0.1, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    this._uniforms(patch, eye, vp, display);
    for (const mesh of this.meshes[patch ? "patch" : "scene"]) {
      gl.bindVertexArray(mesh.vao);
      gl.drawArrays(gl.TRIANGLES, 0, mesh.count);
    }
    gl.bindVertexArray(null);
  }

  _sync() {   // wait for the GPU: read one pixel
    const gl = this.gl, px = new Uint8Array(4);
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
  }

  // Linear radiance (n x n x 4 floats, row 0 = v = 0) of the patch at MIP `level`, one pixel
  // per texel of that level: the view of microfacet.leadr.figures.render_level.
  renderPatch({ method = 1, level = 0, light = 0, supersampling = null } = {}) {
    const gl = this.gl;
    const [n, m] = this.meta.leadr[level];
    const saved = { ...this.state };
    Object.assign(this.state, { method, light, diffuse: false,
                                supersampling: supersampling ?? 2 ** level });
    const tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, tex);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32F, m, n);
    const fbo = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, fbo);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, tex, 0);
    this.draw(m, n, { patch: true, display: false });
    const out = new Float32Array(n * m * 4);
    gl.readPixels(0, 0, m, n, gl.RGBA, gl.FLOAT, out);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.deleteFramebuffer(fbo);
    gl.deleteTexture(tex);
    this.state = saved;
    const flipped = new Float32Array(n * m * 4);    // GL rows go bottom-up
    for (let r = 0; r < n; ++r) flipped.set(out.subarray((n - 1 - r) * m * 4, (n - r) * m * 4), r * m * 4);
    return Array.from(flipped);
  }

  // Mean frame time (ms) of `frames` synchronized frames of the scene (or, with `patch`, of
  // the uv square filling the viewport) at w x h, after `warmup` frames.
  benchmark({ method = 1, light = 0, supersampling = 4, width = 1280, height = 720, frames = 3, warmup = 1,
              patch = false } = {}) {
    const saved = { ...this.state };
    Object.assign(this.state, { method, light, supersampling });
    this.canvas.width = width;
    this.canvas.height = height;
    for (let i = 0; i < warmup; ++i) { this.draw(width, height, { patch }); this._sync(); }
    const t0 = performance.now();
    for (let i = 0; i < frames; ++i) { this.draw(width, height, { patch }); this._sync(); }
    const ms = (performance.now() - t0) / frames;
    this.state = saved;
    return ms;
  }

  _bindUi() {
    const s = this.state;
    document.querySelectorAll("input[name=method]").forEach((e) => e.addEventListener("change", () => { s.method = +e.value; this.dirty = true; }));
    document.querySelectorAll("input[name=light]").forEach((e) => e.addEventListener("change", () => { s.light = +e.value; this.dirty = true; }));
    document.getElementById("ss").addEventListener("change", (e) => { s.supersampling = +e.target.value; this.dirty = true; });
    document.getElementById("diffuse").addEventListener("change", (e) => { s.diffuse = e.target.checked; this.dirty = true; });
    document.getElementById("exposure").addEventListener("input", (e) => { s.exposure = +e.target.value; this.dirty = true; });
    let drag = null;
    this.canvas.addEventListener("pointerdown", (e) => { drag = [e.clientX, e.clientY, e.shiftKey]; });
    window.addEventListener("pointerup", () => { drag = null; });
    window.addEventListener("pointermove", (e) => {
      if (!drag) return;
      const dx = (e.clientX - drag[0]) * 0.01, dy = (e.clientY - drag[1]) * 0.01;
      if (drag[2]) { s.lightYaw -= dx; s.lightPitch = Math.min(1.5, Math.max(0.05, s.lightPitch + dy)); }
      else { s.yaw -= dx; s.pitch = Math.min(1.5, Math.max(0.02, s.pitch + dy)); }
      drag = [e.clientX, e.clientY, drag[2]];
      this.dirty = true;
    });
    this.canvas.addEventListener("wheel", (e) => { s.distance = Math.min(30, Math.max(0.8, s.distance * Math.exp(e.deltaY * 0.001))); this.dirty = true; e.preventDefault(); }, { passive: false });
    this.dirty = true;
  }

  _loop() {
    const frame = () => {
      const c = this.canvas, w = c.clientWidth | 0, h = c.clientHeight | 0;
      if (c.width !== w || c.height !== h) { c.width = w; c.height = h; this.dirty = true; }
      if (this.dirty && w > 0 && h > 0) {
        const t0 = performance.now();
        this.draw(w, h);
        this._sync();
        const ms = performance.now() - t0;
        this.frameMs = Number.isFinite(this.frameMs) ? 0.8 * this.frameMs + 0.2 * ms : ms;
        document.getElementById("stats").textContent = `frame: ${this.frameMs.toFixed(1)} ms`;
        this.dirty = false;
        this.frames = (this.frames || 0) + 1;
      }
      requestAnimationFrame(frame);
    };
    requestAnimationFrame(frame);
  }
}
