"""Blender add-on "Import microfacet fit": File > Import > microfacet fit (.npz/.json).

Zipped with :mod:`blender_nodes` by :func:`microfacet.export.blender.write_addon`; this file is
the add-on's ``__init__.py`` and runs inside Blender only (it imports ``bpy``), without the
``microfacet`` library: it reads

* a fit file of ``microfacet fit`` (``.npz``): its analytic fit ``model`` (``best``: the file's
  best fit, or when that is the tabulated one the analytic fit of least image error in the
  ``.json`` summary beside it, else the first analytic fit);
* a material description (``.json``, written by ``microfacet export --to blender``) or a BRDF
  spec (``.json``, :mod:`microfacet.fit.spec`);

maps it with :func:`blender_nodes.closures_of_spec` and adds the material (assigned to the
selected mesh objects), reporting as warnings what Blender could not carry.
"""
import json
import os

import bpy
import numpy as np
from bpy.props import StringProperty
from bpy_extras.io_utils import ImportHelper

from . import blender_nodes

bl_info = {
    "name": "Import microfacet fit",
    "author": "microfacet developers",
    "version": (0, 2, 0),
    "blender": (4, 2, 0),
    "location": "File > Import > microfacet fit (.npz/.json)",
    "description": "Import a microfacet BRDF fit (microfacet fit OUT.npz, or an exported .json) as a Cycles material",
    "category": "Import-Export",
}


def fit_spec(path: str, model: str = "best") -> tuple:
    """``(name, spec)`` of the analytic fit ``model`` of the fit file ``path`` (module docstring)."""
    with np.load(path, allow_pickle=False) as data:
        if "fits" not in data:
            raise ValueError(f"{path}: the fit file holds no analytic fit (only the tabulated one)")
        fits = json.loads(str(data["fits"]))
        best = str(data["best"]) if "best" in data else "tabulated"
    if model != "best":
        if model not in fits:
            raise ValueError(f"{path}: no fit named {model!r}; the file has: best, {', '.join(fits)}")
        return model, fits[model]
    if best not in fits:
        best = next(iter(fits))
        summary = os.path.splitext(path)[0] + ".json"
        try:
            with open(summary) as f:
                metrics = {n: v["metrics"] for n, v in json.load(f).get("fits", {}).items()
                           if n in fits and {"image", "log"} <= set(v.get("metrics", {}))}
            if metrics:
                best = _best_fit(metrics)
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            pass
    return best, fits[best]


def _best_fit(metrics: dict) -> str:
    """microfacet.fit.outputs.best_fit's rule, restated (this add-on runs without microfacet):
    leave out fits whose albedo is off by more than 50 %, then those with a colour cast
    (chromaticity > 0.02); the least image x log error, or a fit within 5 % of the data's
    albedo that scores within 2 times it."""
    def score(n):
        return float(metrics[n]["image"]) * float(metrics[n]["log"])
    sound = [n for n in metrics if float(metrics[n].get("albedo_error", 0.0)) <= 0.5] or list(metrics)
    clean = [n for n in sound if float(metrics[n].get("chromaticity", 1.0)) <= 0.02] or sound
    best = min(clean, key=score)
    held = [n for n in clean if float(metrics[n].get("albedo_error", 1.0)) <= 0.05]
    if held and score(min(held, key=score)) <= 2.0 * score(best):
        return min(held, key=score)
    return best


def load_description(path: str, model: str = "best") -> tuple:
    """``(description, lost)`` of a fit file or a JSON file (module docstring)."""
    name = os.path.splitext(os.path.basename(path))[0]
    if path.lower().endswith(".npz"):
        fit, spec = fit_spec(path, model)
        return blender_nodes.closures_of_spec(spec, name=f"{name} ({fit})")
    with open(path) as f:
        data = json.load(f)
    if isinstance(data, dict) and data.get("format") == blender_nodes.FORMAT:
        return data, []
    if isinstance(data, dict) and "type" in data:
        return blender_nodes.closures_of_spec(data, name=name)
    raise ValueError(f"{path}: neither a microfacet material description nor a BRDF spec")


class IMPORT_OT_microfacet_fit(bpy.types.Operator, ImportHelper):
    """Import a microfacet fit (.npz) or material (.json) as a Cycles material"""
    bl_idname = "import_scene.microfacet_fit"
    bl_label = "Import microfacet fit"
    bl_options = {"REGISTER", "UNDO"}
    filename_ext = ".npz"
    filter_glob: StringProperty(default="*.npz;*.json", options={"HIDDEN"})
    model: StringProperty(name="Fit", default="best", description="fit of the file: best, or a fit's name")

    def execute(self, context):
        try:
            desc, lost = load_description(self.filepath, self.model)
        except (OSError, ValueError, KeyError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        mat = blender_nodes.build_material(bpy, desc)
        for ob in getattr(context, "selected_objects", []) or []:
            if ob.type == "MESH":
                if ob.data.materials:
                    ob.data.materials[0] = mat
                else:
                    ob.data.materials.append(mat)
        for line in lost:
            self.report({"WARNING"}, f"not carried: {line}")
        self.report({"INFO"}, f"material {mat.name!r}")
        return {"FINISHED"}


def _menu(self, context):
    self.layout.operator(IMPORT_OT_microfacet_fit.bl_idname, text="microfacet fit (.npz/.json)")


def register():
    bpy.utils.register_class(IMPORT_OT_microfacet_fit)
    bpy.types.TOPBAR_MT_file_import.append(_menu)


def unregister():
    bpy.types.TOPBAR_MT_file_import.remove(_menu)
    bpy.utils.unregister_class(IMPORT_OT_microfacet_fit)
