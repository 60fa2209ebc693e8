"""Mitsuba 3 BSDF plugins of ``microfacet`` (Dr.Jit), registered per variant.

Plugins (:data:`PLUGINS`): ``mf_microfacet`` (:mod:`microfacet.mitsuba.bsdf`), the noncentral
microfacet BRDF of :class:`microfacet.MicrofacetBRDF`; ``mf_fitted``
(:mod:`microfacet.mitsuba.fitted`), a fit of :mod:`microfacet.fit`; ``mf_leadr``
(:mod:`microfacet.mitsuba.leadr`), a LEADR pyramid of :mod:`microfacet.leadr` over a base
material; ``mf_glints`` (:mod:`microfacet.mitsuba.glints`), the patch BRDF of a glint
microsurface. ``mi.set_variant`` is global and plugins are registered per variant: call
:func:`register` again after switching variants (``llvm_ad_rgb``, ``scalar_rgb``,
``*_spectral``, ``*_mono``, ``cuda_*``).

A bad parameter or file raises :class:`PluginParameterError` in the plugin. Mitsuba's
``mi.load_dict`` / ``mi.load_file`` wrap it in a ``RuntimeError`` whose text is Mitsuba's
location, the Python traceback (nanobind formats it into the message) and, last, our
line; :func:`load_dict` and :func:`load_file` are the same loaders that raise our one
line instead, with Mitsuba's location appended.

Each plugin class documents its parameters in one table of its docstring;
:func:`plugin_reference` returns them all as Markdown (:mod:`microfacet.mitsuba.reference`).

Examples
--------
Register the plugins, load one and evaluate it once: a GGX gold lobe seen and lit from
the normal, where ``f_r cos theta_i = F(1) D(n) / 4`` (Eq. 2.1) with
``D(n) = 1 / (pi alpha^2)``:

>>> import mitsuba as mi
>>> mi.set_variant("scalar_rgb")
>>> import microfacet.mitsuba as mfm
>>> mfm.register() == mfm.PLUGINS
True
>>> bsdf = mfm.load_dict({"type": "mf_microfacet", "distribution": "ggx", "alpha_u": 0.2,
...                       "alpha_v": 0.4, "rho": 0.3, "mean_slope_u": 0.1, "material": "Au"})
>>> si = mi.SurfaceInteraction3f()
>>> si.wi = mi.Vector3f(0, 0, 1)
>>> value = mfm.load_dict({"type": "mf_microfacet", "distribution": "ggx", "alpha": 0.3}).eval(
...     mi.BSDFContext(), si, mi.Vector3f(0, 0, 1))
>>> round(value[0], 4), round(1 / (4 * 3.14159265 * 0.3**2), 4)
(0.8842, 0.8842)
"""
from __future__ import annotations

import re

from ..errors import MicrofacetError
from .reference import plugin_reference

__all__ = ["register", "load_dict", "load_file", "PLUGINS", "PluginParameterError", "plugin_reference"]

#: The plugins :func:`register` registers.
PLUGINS = ("mf_microfacet", "mf_fitted", "mf_leadr", "mf_glints")


class PluginParameterError(MicrofacetError, ValueError):
    """A plugin parameter or the file it names is unusable; the one-line message names the
    plugin, the parameter and the file.

    A :class:`~microfacet.errors.MicrofacetError` and a ``ValueError``.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet.mitsuba as mfm
    >>> _ = mfm.register()
    >>> try:
    ...     mfm.load_dict({"type": "mf_microfacet", "alpha": -1.0})
    ... except mfm.PluginParameterError as e:
    ...     print(e)
    mf_microfacet: parameter 'alpha' must be a finite number > 0, got -1.0 (at dictionary node "root")
    """


def _mitsuba():
    try:
        import mitsuba as mi
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise RuntimeError("microfacet.mitsuba needs Mitsuba 3: pip install 'microfacet[mitsuba]'") from e
    return mi


def register() -> tuple[str, ...]:
    """Register the plugins of :data:`PLUGINS` for the current Mitsuba variant.

    The plugins that do not support the variant (all of them in the polarized variants) are
    registered too, as a factory that raises a one-line :class:`PluginParameterError` naming
    the variant.

    Returns
    -------
    tuple of str
        The names of the plugins that support the variant.

    Raises
    ------
    RuntimeError
        If Mitsuba is missing or no variant is set.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet.mitsuba as mfm
    >>> mfm.register()
    ('mf_microfacet', 'mf_fitted', 'mf_leadr', 'mf_glints')
    >>> mfm.load_dict({"type": "mf_microfacet", "alpha": 0.2})      # doctest: +ELLIPSIS
    MicrofacetBSDF[mf_microfacet, distribution=beckmann, gaf=smith, ...]
    """
    mi = _mitsuba()
    if not mi.variant():
        raise RuntimeError("microfacet.mitsuba.register(): set a Mitsuba variant first "
                           "(mi.set_variant('llvm_ad_rgb'))")
    from . import bsdf, fitted, glints, leadr
    names = []
    for module in (bsdf, fitted, leadr, glints):
        try:
            factory = _factory(module.bsdf_class())
            names.append(module.PLUGIN)
        except RuntimeError as e:        # a variant the plugin does not support (polarized)
            factory = _refusal(f"{module.PLUGIN}: {e}")
        mi.register_bsdf(module.PLUGIN, factory)
    return tuple(names)


def _factory(cls):
    def construct(props):
        try:
            return cls(props)
        except PluginParameterError as e:   # drop our frames from the traceback Mitsuba prints
            raise PluginParameterError(str(e)) from None
    return construct


def _refusal(reason: str):
    def construct(props):
        raise PluginParameterError(reason)
    return construct


_LOCATION = re.compile(r"^\[[^\]]*\] At (.*?): failed to instantiate", re.S)
_OURS = re.compile(rf"^{PluginParameterError.__name__}: (.*)$", re.M)


def _one_line(error: RuntimeError) -> PluginParameterError | None:
    """Our error inside Mitsuba's ``RuntimeError``: our line plus Mitsuba's location."""
    text = str(error)
    ours = _OURS.findall(text)
    if not ours:
        return None
    where = _LOCATION.match(text)
    return PluginParameterError(ours[-1] + (f" (at {where.group(1)})" if where else ""))


def _load(loader, *args, **kwargs):
    """``loader(*args, **kwargs)``, our error inside Mitsuba's raised as one line."""
    try:
        return loader(*args, **kwargs)
    except RuntimeError as e:
        ours = _one_line(e)
        if ours is None:
            raise
    raise ours


def load_dict(scene: dict, **kwargs):
    """``mi.load_dict(scene, **kwargs)`` with our errors as one line.

    A bad plugin parameter or file raises :class:`PluginParameterError` with one line (ours,
    then Mitsuba's location, e.g. ``(at dictionary node "sphere.bsdf")``), not Mitsuba's
    ``RuntimeError`` with a traceback.

    Parameters
    ----------
    scene : dict
        A scene or plugin dictionary of ``mi.load_dict``.
    **kwargs
        Passed to ``mi.load_dict`` (e.g. ``parallel``).

    Returns
    -------
    object
        The loaded Mitsuba object (a scene, a BSDF, ...).

    Raises
    ------
    PluginParameterError
        For a bad parameter or file of a plugin of :data:`PLUGINS`.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet.mitsuba as mfm
    >>> _ = mfm.register()
    >>> mfm.load_dict({"type": "mf_microfacet", "alpha": 0.2, "material": "Cu"})  # doctest: +ELLIPSIS
    MicrofacetBSDF[mf_microfacet, ..., fresnel=conductor]
    >>> try:
    ...     mfm.load_dict({"type": "scene", "sphere": {"type": "sphere",
    ...                    "bsdf": {"type": "mf_microfacet", "rho": 1.5}}})
    ... except mfm.PluginParameterError as e:
    ...     print(e)
    mf_microfacet: parameter 'rho' must lie in (-1, 1), got 1.5 (at dictionary node "sphere.bsdf")
    """
    return _load(_mitsuba().load_dict, scene, **kwargs)


def load_file(path, **kwargs):
    """``mi.load_file(path, **kwargs)`` with the errors of :func:`load_dict`.

    Parameters
    ----------
    path : str or os.PathLike
        A Mitsuba XML file.
    **kwargs
        Passed to ``mi.load_file`` (scene parameters).

    Returns
    -------
    object
        The loaded Mitsuba object.

    Raises
    ------
    PluginParameterError
        For a bad parameter or file of a plugin, located as ``(at scene.xml (line 1, col 2))``.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> import microfacet.mitsuba as mfm
    >>> _ = mfm.register()
    >>> with open("bsdf.xml", "w") as f:
    ...     _ = f.write('<bsdf version="3.0.0" type="mf_microfacet"><float name="alpha" value="0"/></bsdf>')
    >>> try:
    ...     mfm.load_file("bsdf.xml")
    ... except mfm.PluginParameterError as e:
    ...     print(e)
    mf_microfacet: parameter 'alpha' must be a finite number > 0, got 0.0 (at bsdf.xml (line 1, col 2))
    """
    return _load(_mitsuba().load_file, str(path), **kwargs)
