"""Render with the Mitsuba 3 plugins

Register the library's BSDFs as Mitsuba 3 plugins and render three spheres under a
procedural sky: ``mf_microfacet`` (GGX, gold), Mitsuba's own ``roughconductor`` with the
same parameters (a cross-check: the two should look alike), and ``mf_fitted`` rendering
a tabulated fit of the library (Dupuy 2015, Ch. 4) made here. Needs
``pip install "microfacet[mitsuba]"``; without Mitsuba the script says so and stops.
"""
import sys

import numpy as np

try:
    import mitsuba as mi
except ImportError:
    print("mitsuba is not installed (pip install 'microfacet[mitsuba]'): nothing rendered")
    sys.exit(0)

import microfacet as mf
import microfacet.mitsuba as mfm
from microfacet.mitsuba.demo import choose_variant

mi.set_variant(choose_variant())                  # llvm_ad_rgb where a libLLVM >= 16 runs, else scalar_rgb
size, spp = (128, 32) if mi.variant().startswith("llvm") else (48, 4)     # scalar: one ray at a time

mfm.register()                                    # mf_microfacet, mf_fitted, mf_leadr, mf_glints
print("variant:", mi.variant())

mf.io.write_exr("sky.exr", mf.render.procedural_sky(64, 128))              # lat-long environment
gold = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), fresnel=mf.fresnel.Conductor.metal("Au"))
mf.fit.fit(gold, 32).save("gold_fit.npz")                                 # as `microfacet fit` writes

bsdfs = {"mf_microfacet": {"type": "mf_microfacet", "distribution": "ggx", "alpha": 0.2, "material": "Au"},
         "roughconductor": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.2, "material": "Au"},
         "mf_fitted": {"type": "mf_fitted", "filename": "gold_fit.npz", "use": "tabulated"}}
images = []
for name, bsdf in bsdfs.items():
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 30,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4.2], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": size, "height": size}},
        "light": {"type": "envmap", "filename": "sky.exr"},
        "sphere": {"type": "sphere", "bsdf": bsdf}})
    image = np.asarray(mi.render(scene, spp=spp))
    print(f"{name}: mean radiance {image.mean():.4f}")
    images.append(image)
mf.io.write_png("mitsuba_spheres.png", np.concatenate(images, axis=1))   # the three, left to right
