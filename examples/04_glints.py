"""Glints: the P-BRDF of a scratched normal map

Turn a scratched-metal normal map into a mixture of Beckmann lobes, one per texel
(Chermain, Claux & Mérillou 2019, Sec. 3), and render a plane under a point light where
each pixel evaluates the P-BRDF of its Gaussian footprint (Eq. 7): the glints of the
scratches, without noise. Beside it: naive rendering at 16 samples per pixel (random
positions of the normal map, each a near-mirror lobe), the reference the P-BRDF
approximates, and the normal map.
"""
import numpy as np

import microfacet as mf
from microfacet.glints.figures import PlaneScene, render_naive, render_pbrdf, scratched_normal_map

normals = scratched_normal_map(512, scratches=160, seed=0)         # (512, 512, 3) unit normals
ms = mf.glints.Microsurface.from_normal_map(normals)               # one Beckmann lobe per texel
print(f"{ms.n_lobes} lobes")

# one P-BRDF: the footprint of a 2-texel Gaussian at the map's centre, as a BRDF
footprint = np.eye(2) * (2 / 512) ** 2
brdf = ms.pbrdf((0.5, 0.5), footprint)
wo = np.array([0.0, -np.sin(np.radians(40)), np.cos(np.radians(40))])
print("directional albedo at 40 degrees:", round(float(brdf.albedo(wo)), 4))

scene = PlaneScene(width=256, view_deg=50.0, light=(0.0, 0.35, 0.9))   # 2 texels per pixel
pbrdf = render_pbrdf(ms, scene)                                      # noise free
naive = render_naive(ms, scene, spp=16, seed=1)                      # Monte Carlo, noisy
exposure = -np.log2(np.percentile(pbrdf, 99.5))
mf.io.write_png("glints.png", np.concatenate([pbrdf, naive], axis=1), exposure)   # P-BRDF | naive
mf.io.write_png("normal_map.png", ((normals[::2, ::2] + 1) / 2) ** 2.2)      # the usual colours
