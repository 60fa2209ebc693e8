"""``microfacet view PYRAMID.exr``: the WebGL2 viewer of a LEADR pyramid on a local web server."""
from __future__ import annotations

import sys

from ..errors import MicrofacetError
from .common import float_in, int_at_least


def add(sub) -> None:
    p = sub.add_parser(
        "view", help="view a LEADR pyramid in the browser (WebGL2): naive MIP vs LEADR vs supersampled reference",
        description="Serve a WebGL2 viewer of PYRAMID.exr (from 'microfacet bake') on 127.0.0.1 and print its "
                    "URL; Ctrl-C stops it. A plane and a sphere carry the map, merged with the base material "
                    "(thesis Ch. 5); switch between naive MIP mapping (averaged normals), LEADR and an NxN "
                    "supersampled reference, a point light and an environment; the frame time is shown. "
                    "The shaders are the package's GLSL (microfacet.glsl).")
    p.add_argument("pyramid", metavar="PYRAMID.exr", help="moment pyramid written by 'microfacet bake'")
    base = p.add_mutually_exclusive_group()
    base.add_argument("--material", metavar="FIT.npz",
                      help="a fit from 'microfacet fit': the base material (Beckmann moments) and Fresnel table")
    base.add_argument("--roughness", type=float_in(0.0, 1e3, open_lo=True), metavar="A",
                      help="isotropic Beckmann base roughness (default 0.1; silver Fresnel)")
    p.add_argument("--env", metavar="ENV.exr", help="lat-long environment (default: a procedural studio sky)")
    p.add_argument("--port", type=int_at_least(0, 65535), default=0, metavar="N",
                   help="port on 127.0.0.1 (default 0: a free port)")
    p.set_defaults(run=run)


def run(args) -> int:
    from ..glsl.server import HOST, load_viewer_data, make_server
    data = load_viewer_data(args.pyramid, material=args.material, roughness=args.roughness, env_path=args.env)
    try:
        server = make_server(data, args.port)
    except OSError as e:
        raise MicrofacetError(f"cannot listen on {HOST}:{args.port} ({e.strerror or e})") from None
    try:
        print(f"http://{HOST}:{server.server_address[1]}/", flush=True)
        print("Ctrl-C stops the server", file=sys.stderr, flush=True)
        server.serve_forever()
    except KeyboardInterrupt:
        print("stopped", file=sys.stderr)
    finally:
        server.server_close()
    return 0
