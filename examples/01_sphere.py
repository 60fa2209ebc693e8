"""GGX and Beckmann spheres and their lobes

Evaluate two microfacet BRDFs of the same roughness (Dupuy 2015, Eq. 2.1: a GGX and a
Beckmann slope distribution, gold's Fresnel term, Smith's height-correlated shadowing),
render each on an orthographic sphere under a directional light and plot their lobes.
GGX's longer tail shows as a wider halo around the highlight.
"""
import numpy as np

import microfacet as mf
from microfacet.render import DirectionalLight, Sphere, save_lobe_figure, shade_directional

gold = mf.fresnel.Conductor.metal("Au")
brdfs = {"GGX": mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=gold),
         "Beckmann": mf.MicrofacetBRDF(mf.Beckmann(alpha=0.3), fresnel=gold)}

# one value: f_r (RGB) for a light 30 degrees left of the normal, the view 30 degrees right
wi = mf.geometry.spherical_to_cartesian(np.radians(30), np.pi)
wo = mf.geometry.spherical_to_cartesian(np.radians(30), 0.0)
for name, brdf in brdfs.items():
    print(f"{name}: f_r at the mirror direction = {np.round(brdf.eval(wi, wo), 3)}")

# spheres: one shading point per pixel, in each pixel's local frame
sphere = Sphere(192)
light = DirectionalLight(direction=(-0.5, 0.5, 1.0), irradiance=3.0)
images = [sphere.image(shade_directional(b, sphere.wo, sphere.to_local(light.w), light.rgb))
          for b in brdfs.values()]
mf.io.write_png("spheres.png", np.concatenate(images, axis=1))     # GGX | Beckmann

# lobes: f_r cos(theta_i) in the plane of incidence, views at 0, 30 and 60 degrees
save_lobe_figure("lobes.png", list(brdfs.values()), list(brdfs), theta_o_deg=(0, 30, 60))
