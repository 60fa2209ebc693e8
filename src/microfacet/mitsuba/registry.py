"""Plugin classes of :mod:`microfacet.mitsuba` for the current Mitsuba variant.

``mi.BSDF`` is a different class in each Mitsuba variant and exists only once a variant is
set, so the plugins are written as plain module-level classes (``MicrofacetBSDF`` in
:mod:`.bsdf`, ``FittedBSDF``, ``LeadrBSDF``, ``GlintsBSDF``, ``TreeBSDF``) and
:func:`variant_class` makes, once per variant, the subclass of that variant's ``mi.BSDF``
with the plain class's namespace (its methods and those of its plain bases): the class
Mitsuba instantiates, as its own Python plugins are registered with ``mi.register_bsdf``.
Plain plugin classes therefore call their bases by name (``MicrofacetBSDF.sample(self,
...)``), never ``super()``, and start ``__init__`` with ``mi.BSDF.__init__(self, props)``.
"""
from __future__ import annotations

import mitsuba as mi

__all__ = ["variant_class", "namespace"]

_CLASSES: dict[tuple[str, type], type] = {}
_SKIP = ("__dict__", "__weakref__")


def namespace(plugin: type) -> dict:
    """The attributes of a plain plugin class and of its plain bases.

    The nearest class wins, as in Python's method resolution; ``object``'s attributes and
    ``__dict__``/``__weakref__`` are left out.

    Parameters
    ----------
    plugin : type
        A plain plugin class (e.g. :class:`~microfacet.mitsuba.leadr.LeadrBSDF`).

    Returns
    -------
    dict
        Attribute name -> value.

    Examples
    --------
    >>> from microfacet.mitsuba.registry import namespace
    >>> from microfacet.mitsuba.bsdf import MicrofacetBSDF, MicrofacetLobe
    >>> ns = namespace(MicrofacetBSDF)
    >>> ns["lobe_eval_pdf"] is MicrofacetLobe.lobe_eval_pdf, ns["eval"] is MicrofacetBSDF.eval
    (True, True)
    """
    out: dict = {}
    for cls in reversed(plugin.__mro__[:-1]):
        out.update({k: v for k, v in vars(cls).items() if k not in _SKIP})
    return out


def variant_class(plugin: type) -> type:
    """The subclass of the current variant's ``mi.BSDF`` with the namespace of ``plugin``.

    Built once per variant and plugin (:func:`namespace`); Mitsuba instantiates it.

    Parameters
    ----------
    plugin : type
        A plain plugin class.

    Returns
    -------
    type
        A subclass of ``mi.BSDF`` of the current variant.

    Raises
    ------
    RuntimeError
        For a polarized variant (the plugins compute unpolarized spectra) or when no variant
        is set.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.registry import variant_class
    >>> from microfacet.mitsuba.bsdf import MicrofacetBSDF
    >>> cls = variant_class(MicrofacetBSDF)
    >>> issubclass(cls, mi.BSDF), variant_class(MicrofacetBSDF) is cls
    (True, True)
    """
    variant = mi.variant()
    if not variant:
        raise RuntimeError("microfacet.mitsuba: set a Mitsuba variant first (mi.set_variant('llvm_ad_rgb'))")
    if mi.is_polarized:
        raise RuntimeError(f"polarized variants are not supported ({variant})")
    key = (variant, plugin)
    if key not in _CLASSES:
        _CLASSES[key] = type(plugin.__name__, (mi.BSDF,), namespace(plugin))
    return _CLASSES[key]
