"""Glints: high-definition specular normal maps as mixtures of Beckmann lobes, their
patch NDF (P-NDF) and patch BRDF (Chermain, Claux and Mérillou 2019).

``ms = Microsurface.from_normal_map(path)`` builds one Beckmann lobe per texel (Sec. 3,
Eq. 1-6); ``ms.pndf(h, center, cov)`` evaluates the P-NDF of a Gaussian footprint (Eq. 9)
through an acceleration hierarchy (Sec. 5); ``ms.pbrdf(center, cov)`` gives the patch
BRDF (Eq. 7) with exact or approximate (MIP, Sec. 4.2.2) patch masking.

Modules: ``microsurface`` (:class:`LobeMixture`: lobes, P-NDF, files) <- ``pbrdf``
(:class:`PatchBRDF` and the public :class:`Microsurface`, a ``LobeMixture`` with
``.pbrdf``) <- ``figures``; ``reference`` needs only ``microsurface``.

Examples
--------
>>> import numpy as np
>>> ms = Microsurface.from_slopes(0.1 * np.random.default_rng(0).standard_normal((8, 8, 2)))
>>> center, cov = [0.5, 0.5], np.eye(2) * 1e-3            # a Gaussian footprint in uv
>>> bool(ms.pndf(np.array([0.0, 0.0, 1.0]), center, cov) > 0)
True
>>> f = ms.pbrdf(center, cov)                               # the patch BRDF, a library BRDF
>>> f.eval_cos(np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0])).shape
(3,)
>>> Microsurface.load(ms.save("scratches.npz")).grid, FORMAT_VERSION
((8, 8), 2)
"""
from .microsurface import FORMAT_VERSION, LobeMixture, interpolate_slopes, load_slopes
from .pbrdf import Microsurface, PatchBRDF, eval_cos_footprints, lobe_projected_area

__all__ = ["Microsurface", "LobeMixture", "load_slopes", "interpolate_slopes", "FORMAT_VERSION",
           "PatchBRDF", "eval_cos_footprints", "lobe_projected_area"]
