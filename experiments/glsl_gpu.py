#!/usr/bin/env python3
"""The GLSL tests on whatever GL this machine has (a GPU's, where the suite's CI runs Mesa
llvmpipe): ``tests/test_glsl.py`` run once, every relative error its comparisons measure
recorded, and the GL's bilinear filter probed (its weight levels; whether they are truncated
or rounded 8-bit weights); with ``FRAMES=n``, the viewer's frame times at 1280x720 (naive,
LEADR, 4x4 and 8x8 references; the GL's filter and ``MF_MANUAL_BILINEAR``; mean of ``n``
frames, the 8x8 reference one). Writes ``$OUT/glsl_gpu.json`` (or ``./``).

Usage (repository root; the NumPy path as the reference, no Numba compile)::

    MICROFACET_NUMBA=0 PYTHONPATH=src python3 experiments/glsl_gpu.py

On the lent NVIDIA machines (no package index there) the run carried cp312 wheels of
moderngl, glcontext, openexr, imagecodecs, tqdm, threadpoolctl and the glvnd/EGL .debs of
``/work/.library/device/README.md``, and set ``__EGL_VENDOR_LIBRARY_FILENAMES`` to the NVIDIA
vendor file; results in ``experiments/results/glsl_gpu.md``.
"""
import json, os, sys
import numpy as np
import pytest

errors = {}


class Record:
    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_call(self, item):
        mod = item.module
        orig = getattr(mod, "rel_error", None)
        if orig is not None:
            def rec(gpu, ref, _orig=orig, _id=item.nodeid):
                e = _orig(gpu, ref)
                errors.setdefault(_id, []).append(e)
                return e
            mod.rel_error = rec
        yield
        if orig is not None:
            mod.rel_error = orig


def frame_times(frames, width, height):
    """``benchmarks/bench_view.py``'s patch frame times on this GL (256² map), point light and
    environment, with the GL's filter and with ``MF_MANUAL_BILINEAR``: ``{config: {method: ms}}``."""
    import argparse
    import tempfile
    from pathlib import Path
    sys.path.insert(0, "benchmarks")
    import bench_view as V
    from microfacet.glsl.server import load_viewer_data
    from microfacet.leadr import bake, figures, write_pyramid
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "map.exr"
        write_pyramid(path, bake(figures.default_heightfield(256, 3), 1.0))
        data = load_viewer_data(path)
    out = {}
    for light in (0, 1):
        for name, defines in (("hardware", None), ("manual", {"MF_MANUAL_BILINEAR": None})):
            args = argparse.Namespace(width=width, height=height, frames=frames, light_kind=light)
            out[f"{('point', 'env')[light]} {name}"] = V.bench_llvmpipe(data, args, defines)
    return out


def main():
    import moderngl
    ctx = moderngl.create_standalone_context(backend="egl", require=330)
    info = {k: ctx.info[k] for k in ("GL_VENDOR", "GL_RENDERER", "GL_VERSION")}
    print(info, flush=True)
    code = pytest.main(["-q", "-rA", "-p", "no:cacheprovider", "tests/test_glsl.py"], plugins=[Record()])
    sys.path.insert(0, ".")
    from tests import test_glsl as T
    from microfacet.glsl import harness
    w = T.filter_weights(harness, T.PROBE_U)
    probe = {"levels": int(np.unique(w).size), "first": w[:40].tolist()}
    exact = np.arange(T.PROBE_U.size) / 4096
    probe["trunc8"] = bool(np.array_equal(np.floor(exact * 256) / 256, w))
    probe["round8"] = bool(np.array_equal(np.floor(exact * 256 + 0.5) / 256, w))
    print("probe", {k: v for k, v in probe.items() if k != "first"}, flush=True)
    frames = int(os.environ.get("FRAMES", "0"))
    times = frame_times(frames, 1280, 720) if frames else None
    out = {"gl": info, "exit": int(code), "probe": probe, "frame_ms": times, "errors": {k: max(v) for k, v in errors.items()},
           "all": errors}
    path = os.path.join(os.environ.get("OUT", "."), "glsl_gpu.json")
    with open(path, "w") as f:
        json.dump(out, f, indent=1)
    for k, v in sorted(out["errors"].items()):
        print(f"{v:.3e}  {k}")
    return code


if __name__ == "__main__":
    sys.exit(main())
