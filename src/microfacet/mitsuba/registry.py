"""Plugin classes of :mod:`microfacet.mitsuba` for the current Mitsuba variant.

``mi.BSDF`` is a different class in each Mitsuba variant and exists only once a variant is
set, so the plugins are written as plain module-level classes (``MicrofacetBSDF`` in
:mod:`.bsdf`, ``FittedBSDF``, ``LeadrBSDF``, ``GlintsBSDF``, ``TreeBSDF``) and
:func:`variant_class` makes, once per variant, the subclass of that variant's ``mi.BSDF``
with the plain class's namespace (its methods and those of its plain bases): the class
Mitsuba instantiates, as its own Python plugins are registered with ``mi.register_bsdf``.
Plain plugin classes therefore call their bases by name (``MicrofacetBSDF.sample(self,
...)``), never ``super()``, and start ``__init__`` with ``mi.BSDF.__init__(self, props)``.

Example::

    mi.set_variant("scalar_rgb")
    cls = variant_class(MicrofacetBSDF)       # a subclass of mi.BSDF (scalar_rgb)
    assert variant_class(MicrofacetBSDF) is cls
"""
from __future__ import annotations

import mitsuba as mi

__all__ = ["variant_class", "namespace"]

_CLASSES: dict[tuple[str, type], type] = {}
_SKIP = ("__dict__", "__weakref__")


def namespace(plugin: type) -> dict:
    """The attributes of the plain class ``plugin`` and of its plain bases (the nearest one
    wins, as in Python's method resolution), without ``object``'s."""
    out: dict = {}
    for cls in reversed(plugin.__mro__[:-1]):
        out.update({k: v for k, v in vars(cls).items() if k not in _SKIP})
    return out


def variant_class(plugin: type) -> type:
    """The subclass of the current variant's ``mi.BSDF`` with the namespace of ``plugin``
    (:func:`namespace`), built once per variant; ``RuntimeError`` for a polarized variant
    (the plugins compute unpolarized spectra) or when no variant is set."""
    variant = mi.variant()
    if not variant:
        raise RuntimeError("microfacet.mitsuba: set a Mitsuba variant first (mi.set_variant('llvm_ad_rgb'))")
    if mi.is_polarized:
        raise RuntimeError(f"polarized variants are not supported ({variant})")
    key = (variant, plugin)
    if key not in _CLASSES:
        _CLASSES[key] = type(plugin.__name__, (mi.BSDF,), namespace(plugin))
    return _CLASSES[key]
