"""Export a fit to glTF

Fit a material, export its best analytic fit as a glTF 2.0 material (a ``.glb`` that
Blender, three.js or any glTF viewer opens) and check what the export keeps: the
material read back from the file is evaluated as the glTF specification defines it
(GGX, Schlick's Fresnel term, ``KHR_materials_*`` extensions) and rendered beside the
fit. The report says what glTF cannot carry and the image error of the export.
"""

import numpy as np

import microfacet as mf
from microfacet.export import export, gltf_brdf, read_material
from microfacet.render import DirectionalLight, Sphere, shade_directional

# a material to fit: rough copper over a faint diffuse base (or a measured file, 02_fit_measured.py)
copper = mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.25), fresnel=mf.fresnel.Conductor.metal("Cu")),
                        mf.Lambertian((0.03, 0.02, 0.02)))
ggx = mf.fit.fit_analytic(copper, "ggx", diffuse=True)

report = export(ggx, "gltf", "copper.glb")          # writes copper.glb and its report beside it
print("written:", report["file"])
for loss in report["lost"]:
    print("lost in the export:", loss)
print("image error of the glTF material against the fit:",
      {k: round(v, 4) for k, v in report["image_error"]["exported_vs_fit"].items()})

material = read_material("copper.glb")              # the glTF material as a JSON dict
pbr = material["pbrMetallicRoughness"]
print("baseColorFactor", np.round(pbr["baseColorFactor"], 4).tolist(), "metallicFactor", pbr.get("metallicFactor"),
      "roughnessFactor", round(pbr["roughnessFactor"], 4), "extensions", sorted(material.get("extensions", {})))
as_gltf = gltf_brdf(material)                       # the glTF material as the library evaluates it

sphere = Sphere(160)
light = DirectionalLight(direction=(-0.5, 0.5, 1.0), irradiance=3.0)
images = [sphere.image(shade_directional(b, sphere.wo, sphere.to_local(light.w), light.rgb))
          for b in (copper, ggx, as_gltf)]
mf.io.write_png("gltf_export.png", np.concatenate(images, axis=1))   # material | fit | glTF as held
