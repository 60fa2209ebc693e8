"""Fit a measured material and compare data and fits

Fit a measured BRDF (a MERL ``.binary`` file given on the command line; without one, an
analytic stand-in: GGX aluminium over a faint diffuse base) two ways: the
tabulated microfacet fit of power iterations (Dupuy 2015, Ch. 4) and a least-squares
GGX lobe with a tabulated Fresnel term. The comparison picture shows data and fits on
spheres under two lights, with backscattering and in-plane curves (what ``microfacet fit``
writes beside its ``.npz``; that command tries more models and keeps the one whose
rendered spheres look most like the data).

    python 02_fit_measured.py nickel.binary.gz
"""
import sys

import microfacet as mf

if len(sys.argv) > 1:
    data = mf.measured.load(sys.argv[1])         # MERL, RGL .bsdf or UTIA .bin
    name = mf.io.material_name(sys.argv[1])
else:
    data = mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.15), fresnel=mf.fresnel.Conductor.metal("Al")),
                          mf.Lambertian((0.02, 0.02, 0.02)))
    name = "analytic stand-in"

tabulated = mf.fit.fit(data, resolution=32)                   # the tabulated NDF + Fresnel fit
ggx = mf.fit.fit_analytic(data, "ggx")                        # one GGX lobe (least squares)
tabulated.save("fit.npz")                                     # readable by mf.fit.load, mf_fitted

# how alike they look: the rendered-sphere error of Bieron & Peers 2020 (0 = identical images)
errors = mf.metrics.image_error(data, {"tabulated fit": tabulated, "GGX lobe": ggx}, size=48)
for label, e in errors.items():
    print(f"{name}, {label}: image error {e:.3f}")

mf.render.save_fit_comparison("fit_comparison.png",
                              {"data": data, "tabulated fit": tabulated, "GGX lobe": ggx},
                              title=f"fit of {name}", size=128)
