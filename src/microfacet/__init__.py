"""microfacet — multiscale microfacet rendering in slope space.

Microfacet BRDFs with roughness, correlation and mean slope (Dupuy 2015, Ch. 2-3),
BRDF fitting by power iterations (Ch. 4), LEAN/LEADR prefiltering (Ch. 3, 5) and glints.

Names and submodules are imported on first access (PEP 562 module ``__getattr__``), so
``import microfacet`` and the command line's ``--help`` stay fast: ``mf.GGX`` imports
:mod:`microfacet.distributions`, ``mf.fit`` imports :mod:`microfacet.fit`, and so on.
"""
from __future__ import annotations

import importlib

from .errors import MicrofacetError

__version__ = "0.2.0"
__all__ = ["BRDF", "Beckmann", "GGX", "Lambertian", "MicrofacetBRDF", "MicrofacetError", "TransmittedLambertian",
           "SlopeDistribution", "batch", "fit", "fresnel", "geometry", "glints", "leadr", "measured"]

#: Public names defined in a submodule: name -> that submodule.
_NAMES = {"BRDF": "brdf", "Lambertian": "brdf", "MicrofacetBRDF": "brdf", "TransmittedLambertian": "diffuse",
          "GGX": "distributions", "Beckmann": "distributions", "SlopeDistribution": "distributions"}
#: Submodules reachable as attributes (``mf.metrics``, ``mf.render``, ...) without an import.
_SUBMODULES = frozenset({"anchors", "batch", "brdf", "diffuse", "distributions", "export", "fit", "fresnel", "geometry", "glints", "io", "kernels",
                         "layered", "leadr", "measured", "metrics", "render", "validation"})


def __getattr__(name: str):
    """Import ``name`` on first access (PEP 562) and keep it as a module attribute."""
    if name in _NAMES:
        value = getattr(importlib.import_module(f".{_NAMES[name]}", __name__), name)
    elif name in _SUBMODULES:
        value = importlib.import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_NAMES) | _SUBMODULES)
