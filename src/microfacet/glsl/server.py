"""The viewer's data and its local HTTP server (``microfacet view``).

The server decodes everything with the library and serves it raw, so the page needs no
EXR reader: ``/meta.json`` (sizes, offsets, scene, Fresnel, SH coefficients),
``/leadr.bin`` and ``/naive.bin`` (the merged LEADR and naive moment pyramids, float32,
levels one after the other, each ``(H_k, W_k, 5)``), ``/env.bin`` (the environment's MIP
levels, float32 RGBA), ``/shader/NAME`` (:func:`microfacet.glsl.source` for ES 3.00) and
the page itself (``index.html``, ``viewer.js``: plain ES modules, no build step). It binds
127.0.0.1 only.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path

import numpy as np

from ..errors import MicrofacetError
from .sources import SHADERS, source

__all__ = ["ViewerData", "load_viewer_data", "make_server", "HOST"]

#: The only address the server binds.
HOST = "127.0.0.1"
_STATIC = {"/": ("index.html", "text/html; charset=utf-8"),
           "/index.html": ("index.html", "text/html; charset=utf-8"),
           "/viewer.js": ("viewer.js", "text/javascript; charset=utf-8")}


def _pack(levels) -> tuple[bytes, list]:
    arrays = [np.ascontiguousarray(level, dtype=np.float32) for level in levels]
    return b"".join(a.tobytes() for a in arrays), [list(a.shape) for a in arrays]


@dataclass
class ViewerData:
    """What the page renders: merged LEADR and naive pyramids, environment, lights.

    Attributes
    ----------
    leadr, naive : list of (H_k, W_k, 5) arrays
        The moment pyramids with the base merged in (LEADR: per level; naive: level 0's
        slopes box-filtered).
    env_levels : list of (H, W, 3) arrays
        The environment's MIP levels.
    sh : ndarray
        Its spherical-harmonics coefficients.
    fresnel : dict
        The Fresnel term as the page reads it.
    meta : dict
        Names, the base's moments, the camera, the light.

    Examples
    --------
    ``blobs()`` is what the server sends:

    >>> import microfacet as mf
    >>> _ = mf.leadr.write_pyramid("bumps.exr", mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1)))
    >>> data = load_viewer_data("bumps.exr")
    >>> sorted(data.blobs())
    ['/env.bin', '/leadr.bin', '/meta.json', '/naive.bin']
    """

    leadr: list
    naive: list
    env_levels: list
    sh: np.ndarray
    fresnel: dict
    meta: dict = field(default_factory=dict)

    def blobs(self) -> dict[str, bytes]:
        """The files the page fetches, packed: the pyramids and the environment's levels as
        flat float32 binaries, their shapes with the rest in ``/meta.json``.

        Returns
        -------
        dict of str to bytes
            ``/leadr.bin``, ``/naive.bin``, ``/env.bin`` and ``/meta.json`` by URL path.
        """
        leadr, leadr_shapes = _pack(self.leadr)
        naive, naive_shapes = _pack(self.naive)
        env4 = [np.concatenate([m, np.ones(m.shape[:2] + (1,))], -1) for m in self.env_levels]
        env, env_shapes = _pack(env4)
        meta = dict(self.meta, leadr=leadr_shapes, naive=naive_shapes, env=env_shapes,
                    sh=np.asarray(self.sh, float).tolist(), fresnel=self.fresnel)
        return {"/leadr.bin": leadr, "/naive.bin": naive, "/env.bin": env,
                "/meta.json": json.dumps(meta).encode()}


def load_viewer_data(pyramid_path, material=None, roughness=None, env_path=None) -> ViewerData:
    """Read and prepare the viewer's data (raises :class:`MicrofacetError` naming the bad file).

    ``material`` (a fit ``.npz``) or ``roughness`` (Beckmann alpha, default 0.1) is the base
    merged into every level (:func:`microfacet.leadr.downsample_operator`); the Fresnel
    term is the fit's table or silver (``PatchScene``'s). ``env_path`` is a lat-long EXR
    (default: :func:`microfacet.render.lights.procedural_sky` at ``PatchScene.env_size``).

    Parameters
    ----------
    pyramid_path : str or os.PathLike
        A pyramid EXR (``microfacet bake``).
    material : str or os.PathLike, optional
        A fit ``.npz``: the base material and its Fresnel table.
    roughness : float, optional
        The base's Beckmann alpha when no ``material`` is given.
    env_path : str or os.PathLike, optional
        A lat-long environment EXR.

    Returns
    -------
    ViewerData

    Examples
    --------
    >>> import microfacet as mf
    >>> _ = mf.leadr.write_pyramid("bumps.exr", mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1)))
    >>> data = load_viewer_data("bumps.exr", roughness=0.2)
    >>> [level.shape for level in data.leadr], data.meta["base"]
    ([(8, 8, 5), (4, 4, 5), (2, 2, 5), (1, 1, 5)], 'Beckmann alpha 0.2')
    """
    from .. import fit as _fit
    from ..leadr import downsample_operator, read_pyramid
    from ..leadr.downsample import base_lobe, naive_pyramid
    from ..leadr.figures import PatchScene
    from ..leadr.shading import MipEnvironment, sh_project
    from ..render.lights import Environment, procedural_sky
    scene = PatchScene()
    levels = read_pyramid(pyramid_path)
    if material is not None:
        path = Path(material)
        fit = _fit.load(path)
        base = base_lobe(fit)
        f = fit.fresnel
        c = np.linspace(0.0, 1.0, 64)
        fresnel = dict(kind=4, table=np.column_stack([f(c), c]).tolist())
        base_name = f"fit {path.name}"
    else:
        alpha = 0.1 if roughness is None else float(roughness)
        if not alpha > 0:
            raise MicrofacetError(f"--roughness must be > 0, got {roughness}")
        base = base_lobe(alpha)
        eta, k = scene.fresnel.eta, scene.fresnel.k
        fresnel = dict(kind=3, a=eta.tolist(), b=k.tolist())
        base_name = f"Beckmann alpha {alpha:g}"
    env = MipEnvironment(procedural_sky(*scene.env_size) if env_path is None
                         else Environment.from_exr(env_path).map)
    leadr = downsample_operator(levels, base)
    naive = naive_pyramid(levels[0].astype(np.float64), base)
    meta = dict(name=Path(pyramid_path).name, base=base_name, base_moments=base.tolist(),
                camera=list(scene.camera), light=list(scene.light), intensity=scene.intensity,
                grid=scene.grid, env_size=list(env.map.shape[:2]), env_T=env.texture_size)
    return ViewerData(leadr, naive, [lv.map for lv in env.levels], sh_project(env), fresnel, meta)


def make_server(data: ViewerData, port: int = 0) -> ThreadingHTTPServer:
    """An HTTP server on 127.0.0.1:``port`` (0: a free port) serving the viewer of ``data``;
    raises ``OSError`` when the port is taken.

    Parameters
    ----------
    data : ViewerData
        What to serve (:func:`load_viewer_data`).
    port : int
        The port on :data:`HOST`.

    Returns
    -------
    ThreadingHTTPServer
        The server, not yet serving (call ``serve_forever``).

    Examples
    --------
    >>> import json, threading, urllib.request
    >>> import microfacet as mf
    >>> _ = mf.leadr.write_pyramid("bumps.exr", mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1)))
    >>> server = make_server(load_viewer_data("bumps.exr"))
    >>> threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True).start()
    >>> url = f"http://{HOST}:{server.server_address[1]}"
    >>> json.load(urllib.request.urlopen(url + "/meta.json"))["leadr"][:2]
    [[8, 8, 5], [4, 4, 5]]
    >>> urllib.request.urlopen(url + "/shader/leadr").read().splitlines()[0]
    b'#version 300 es'
    >>> server.shutdown(); server.server_close()
    """
    blobs = data.blobs()
    web = resources.files(__package__).joinpath("web")

    class Handler(BaseHTTPRequestHandler):
        def do_GET(self):  # noqa: N802 - http.server API
            path = self.path.split("?", 1)[0]
            if path in blobs:
                body, kind = blobs[path], ("application/json" if path.endswith(".json")
                                           else "application/octet-stream")
            elif path in _STATIC:
                name, kind = _STATIC[path]
                body = web.joinpath(name).read_bytes()
            elif path.startswith("/shader/") and path[8:] in SHADERS:
                body, kind = source(path[8:], "es300").encode(), "text/plain; charset=utf-8"
            else:
                self.send_error(404)
                return
            self.send_response(200)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, format, *args):   # quiet: the CLI prints the URL only
            if os.environ.get("MICROFACET_VIEW_LOG"):
                super().log_message(format, *args)

    server = ThreadingHTTPServer((HOST, int(port)), Handler)
    server.daemon_threads = True
    return server
