"""Shading harness: an orthographic sphere shaded by any BRDF of the protocol under a
directional light or an environment map (integrated by the BRDF's own importance
sampling), polar lobe plots and fit-comparison pictures.
"""
from .compare import fit_comparison_png, fit_spheres_png, render_sphere, save_fit_comparison
from .integrate import shade_directional, shade_environment, shifted_sobol, sobol_02
from .lights import DirectionalLight, Environment, procedural_sky
from .lobes import plot_lobes, save_lobe_figure
from .sphere import Sphere, tangent_frame

__all__ = ["Sphere", "tangent_frame", "DirectionalLight", "Environment", "procedural_sky",
           "sobol_02", "shifted_sobol", "shade_directional", "shade_environment",
           "plot_lobes", "save_lobe_figure", "render_sphere", "save_fit_comparison", "fit_comparison_png",
           "fit_spheres_png"]
