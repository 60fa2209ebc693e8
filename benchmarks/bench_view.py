#!/usr/bin/env python3
"""Frame time of the viewer's shading: naive MIP vs LEADR vs the N x N supersampled
reference, in headless Chromium (WebGL2 on SwiftShader) and on Mesa llvmpipe (moderngl,
the same GLSL built for 3.30), in one run.

Both render the same fragment shader (``viewer.frag``) over ``--width`` x ``--height``
pixels: the uv square of a baked ``--size``² map filling the viewport (``u_patch``), so
every pixel is shaded once; and, in Chromium only, the interactive scene (plane + sphere).
Each figure is the mean of ``--frames`` frames after one warm-up frame, each frame
synchronized (a 1-pixel read-back in Chromium, ``ctx.finish()`` on llvmpipe). The
machine is shared: compare the ratios within one run.

Usage::

    python benchmarks/bench_view.py [--width 1280] [--height 720] [--size 256] [--frames 2]
                                    [--light point|env] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from microfacet.glsl import harness, source
from microfacet.glsl.browser import open_viewer
from microfacet.glsl.server import load_viewer_data
from microfacet.leadr import bake, figures, write_pyramid

METHODS = [("naive", 0, 0), ("leadr", 1, 0), ("reference 4x4", 2, 4), ("reference 8x8", 2, 8)]
PATCH = np.array([[u, 0, w - 1, u, w, 1, 0, 0, 0, 1, 0] for u, w in
                  [(0, 0), (1, 0), (1, 1), (0, 0), (1, 1), (0, 1)]], dtype=np.float32)


def bench_chromium(data, args) -> dict:
    out = {}
    with open_viewer(data, 640, 360) as page:
        out["renderer"] = page.evaluate("""() => { const gl = document.createElement('canvas').getContext('webgl2');
            const e = gl.getExtension('WEBGL_debug_renderer_info');
            return e ? gl.getParameter(e.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER); }""")
        for view in ("patch", "scene"):
            for name, method, n in METHODS:
                frames = 1 if n == 8 else args.frames
                ms = page.evaluate(f"""mfViewer.benchmark({{method: {method}, light: {args.light_kind},
                    supersampling: {max(n, 1)}, width: {args.width}, height: {args.height}, frames: {frames},
                    warmup: {0 if n == 8 else 1}, patch: {'true' if view == 'patch' else 'false'}}})""")
                out[f"{view}/{name}"] = ms
                print(f"chromium {view:5s} {name:14s} {ms:10.1f} ms", flush=True)
        assert not page.errors, page.errors
    return out


def bench_llvmpipe(data, args, defines=None) -> dict:
    """The patch's frame times on the EGL context's GL (Mesa llvmpipe here; a GPU's where there is
    one: ``experiments/glsl_gpu.py``), ``viewer.frag`` built with ``defines``."""
    import moderngl
    ctx = harness.context()
    prog = ctx.program(vertex_shader=source("viewer.vert", "330"),
                       fragment_shader=source("viewer.frag", "330", defines))
    meta = json.loads(data.blobs()["/meta.json"])
    tex = {}
    for prefix, levels in (("u_leadr", data.leadr), ("u_naive", data.naive)):
        tex[prefix + "_a"] = harness.upload_levels(ctx, [lv[..., :4] for lv in levels])
        tex[prefix + "_b"] = harness.upload_levels(ctx, [lv[..., 4:] for lv in levels])
    tex["u_env"] = harness.upload_levels(ctx, [np.dstack([m, np.ones(m.shape[:2])]) for m in data.env_levels],
                                         (True, False))
    tex["mf_fit_table"] = harness.upload_levels(ctx, [np.zeros((3, 64, 4))], nearest=True)
    to_world = lambda q: (q[0], q[2], -q[1])  # noqa: E731 - PatchScene local -> world
    values = {"u_patch": True, "u_eye": to_world(meta["camera"]), "u_light": to_world(meta["light"]),
              "u_intensity": meta["intensity"], "u_fresnel.kind": meta["fresnel"]["kind"],
              "u_fresnel.a": tuple(meta["fresnel"]["a"]), "u_fresnel.b": tuple(meta["fresnel"]["b"]),
              "u_leadr_top": len(data.leadr) - 1, "u_naive_top": len(data.naive) - 1,
              "u_env_top": len(data.env_levels) - 1, "u_env_T": meta["env_T"], "u_grid": meta["grid"],
              "u_light_kind": args.light_kind, "u_display": False, "u_albedo": (0.0, 0.0, 0.0)}
    for name, value in values.items():
        if name in prog:
            prog[name].value = value
    if "u_sh" in prog:
        prog["u_sh"].write(np.asarray(data.sh, np.float32).tobytes())
    for unit, (name, t) in enumerate(tex.items()):
        t.use(unit)
        if name in prog:
            prog[name].value = unit
    vbo = ctx.buffer(PATCH.tobytes())
    vao = ctx.vertex_array(prog, [(vbo, "3f 2f 3f 3f", "a_position", "a_uv", "a_tangent", "a_normal")])
    target = ctx.texture((args.width, args.height), 4, dtype="f4")
    fbo = ctx.framebuffer(color_attachments=[target])
    fbo.use()
    out = {"renderer": ctx.info["GL_RENDERER"]}
    for name, method, n in METHODS:
        prog["u_method"].value = method
        if "u_supersampling" in prog:
            prog["u_supersampling"].value = max(n, 1)
        frames = 1 if n == 8 else args.frames
        for i in range(frames + (0 if n == 8 else 1)):
            if i == (0 if n == 8 else 1):
                t0 = time.perf_counter()
            vao.render(moderngl.TRIANGLES)
            ctx.finish()
        ms = 1e3 * (time.perf_counter() - t0) / frames
        out[f"patch/{name}"] = ms
        print(f"llvmpipe patch {name:14s} {ms:10.1f} ms", flush=True)
    for obj in (vao, vbo, fbo, target, prog, *tex.values()):
        obj.release()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--height", type=int, default=720)
    ap.add_argument("--size", type=int, default=256, help="side of the baked test map")
    ap.add_argument("--frames", type=int, default=2)
    ap.add_argument("--light", choices=("point", "env"), default="point")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    args.light_kind = 0 if args.light == "point" else 1
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "map.exr"
        write_pyramid(path, bake(figures.default_heightfield(args.size, 3), 1.0))
        data = load_viewer_data(path)
    result = {"machine": platform.processor() or platform.machine(), "width": args.width, "height": args.height,
              "size": args.size, "light": args.light,
              "chromium": bench_chromium(data, args), "llvmpipe": bench_llvmpipe(data, args)}
    print(f"\n{args.width}x{args.height}, {args.light} light, {args.size}² map; ratios to naive (same run):")
    print(f"{'':16s}" + "".join(f"{n:>16s}" for n, _, _ in METHODS))
    for engine, view in (("chromium", "patch"), ("chromium", "scene"), ("llvmpipe", "patch")):
        r = result[engine]
        print(f"{engine + ' ' + view:16s}" + "".join(f"{r[f'{view}/{n}']:10.0f} ms" + f"{r[f'{view}/{n}'] / r[f'{view}/naive']:5.1f}x"[-5:].rjust(6) for n, _, _ in METHODS))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
