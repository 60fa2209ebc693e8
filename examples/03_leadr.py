"""LEADR-prefilter a normal map

Bake a LEAN/LEADR MIP pyramid of slope moments from a height map (Dupuy et al. 2013;
Dupuy 2015, Ch. 3 and 5) and shade a displaced silver patch at coarser and coarser
resolutions under a point light. Top row: the supersampled reference (every level-0
texel shaded and averaged); middle: naive MIP mapping of the normals (the bumps'
roughness is lost and the patch turns mirror-like); bottom: LEADR (one lookup per pixel,
the bumps' slope variance added to the base roughness), which keeps the reference's look.
"""
import numpy as np

import microfacet as mf
from microfacet.leadr.figures import compare_levels

# smooth bumps plus fine anisotropic grooves: two Gaussian random height fields
height = (mf.leadr.gaussian_heightfield((256, 256), 0.25, correlation=48.0, seed=3)
          + mf.leadr.gaussian_heightfield((256, 256), 0.45, 0.15, rho=0.5, correlation=3.0, seed=4))
pyramid = mf.leadr.bake(height, scale=1.0, roughness=0.1)     # [(H_k, W_k, 5) moments, ...]
print("pyramid levels:", [level.shape[:2] for level in pyramid])

# one uv lookup: the filtered slope moments under a 1/16-wide footprint, and their lobe
moments = mf.leadr.lookup(pyramid, np.array([0.5, 0.5]), 1 / 16)
print("moments E1..E5 at the centre:", np.round(moments, 4))

levels = (1, 2, 3, 4)
images, errors = compare_levels(height, base=0.1, levels=levels, kinds=("point",))
side = 128
rows = []
for method in ("reference", "naive", "leadr"):
    cells = []
    for level in levels:
        img = images["point", level][method]
        k = side // img.shape[0]
        cells.append(np.repeat(np.repeat(img, k, axis=0), k, axis=1))     # nearest-neighbour zoom
    rows.append(np.concatenate(cells, axis=1))
exposure = -np.log2(np.percentile(images["point", levels[0]]["reference"], 99.0))   # in stops
mf.io.write_png("leadr_levels.png", np.concatenate(rows, axis=0), exposure)
for level in levels:
    e = errors["point", level]
    print(f"level {level}: relative RMS error naive {e['naive']:.3f}, LEADR {e['leadr']:.3f}")
