"""Reading a Mitsuba plugin's parameters (``mi.Properties``), checked, for every plugin of
:mod:`microfacet.mitsuba` (``mf_microfacet``, ``mf_fitted``, ``mf_leadr``, ``mf_glints``).

A bad parameter raises :class:`~microfacet.mitsuba.PluginParameterError`, one line naming
the plugin and the parameter: ``mf_microfacet: parameter 'alpha_u' must be a finite number >
0, got -1.0`` (:func:`parameter_error`). :func:`texture` reads a float or a texture (a float
checked by a ``check`` such as :func:`positive`), :func:`choice` one of some names,
:func:`flag` a boolean.

Examples
--------
As a plugin's ``__init__(self, props)`` reads its parameters:

>>> import mitsuba as mi
>>> mi.set_variant("scalar_rgb")
>>> from microfacet.mitsuba.properties import DEFAULT_PLUGIN, flag, positive, texture
>>> props = mi.Properties("mf_microfacet")
>>> props["alpha"] = 0.25
>>> alpha = texture(props, "alpha", 0.1, check=positive, plugin=DEFAULT_PLUGIN)
>>> alpha.mean(), flag(props, "shadowing", True)
(0.25, True)

The Fresnel parameters of ``mf_microfacet`` and the term each selects:

>>> from microfacet.mitsuba.properties import FRESNEL_KEYS
>>> FRESNEL_KEYS["material"], FRESNEL_KEYS["int_ior"], FRESNEL_KEYS["schlick_f0"]
('conductor', 'dielectric', 'schlick')
"""
from __future__ import annotations

import math

import mitsuba as mi

from . import PluginParameterError

__all__ = ["DEFAULT_PLUGIN", "FRESNEL_KEYS", "parameter_error", "is_float", "texture", "positive", "finite",
           "correlation", "choice", "flag"]

#: The plugin named in errors when none is given: ``mf_microfacet`` (:mod:`microfacet.mitsuba.bsdf`).
DEFAULT_PLUGIN = "mf_microfacet"
#: Parameters that choose the Fresnel term of ``mf_microfacet``, and the term each implies.
FRESNEL_KEYS = {"material": "conductor", "eta": "conductor", "k": "conductor",
                "int_ior": "dielectric", "ext_ior": "dielectric", "schlick_f0": "schlick",
                "schlick_f90": "schlick"}


def parameter_error(name: str, message: str, plugin: str = DEFAULT_PLUGIN) -> PluginParameterError:
    """The error of parameter ``name`` of ``plugin``: ``"<plugin>: parameter '<name>' <message>"``.

    Parameters
    ----------
    name : str
        The parameter.
    message : str
        What is wrong with it.
    plugin : str, optional
        The plugin (default :data:`DEFAULT_PLUGIN`).

    Returns
    -------
    PluginParameterError
        The error, to raise.

    Examples
    --------
    >>> from microfacet.mitsuba.properties import parameter_error
    >>> str(parameter_error("use", "must name a fit", "mf_fitted"))
    "mf_fitted: parameter 'use' must name a fit"
    """
    return PluginParameterError(f"{plugin}: parameter '{name}' {message}")


def is_float(props, name: str) -> bool:
    """Whether ``props`` holds ``name`` as a number (float or integer).

    Parameters
    ----------
    props : mi.Properties
        The plugin's parameters.
    name : str
        The parameter.

    Returns
    -------
    bool

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.properties import is_float
    >>> props = mi.Properties("mf_microfacet")
    >>> props["alpha"], props["distribution"] = 0.2, "ggx"
    >>> is_float(props, "alpha"), is_float(props, "distribution"), is_float(props, "rho")
    (True, False, False)
    """
    return name in props and props.type(name) in (mi.Properties.Type.Float, mi.Properties.Type.Integer)


def texture(props, name: str, default: float, check=None, unbounded: bool = False, plugin: str = DEFAULT_PLUGIN):
    """Parameter ``name`` as a texture (a float becomes a uniform one), checked.

    Parameters
    ----------
    props : mi.Properties
        The plugin's parameters.
    name : str
        The parameter.
    default : float
        Its value when absent.
    check : callable, optional
        ``check(value) -> message or None`` for a float value (:func:`positive`,
        :func:`finite`, :func:`correlation`).
    unbounded : bool, optional
        Read an unbounded texture (values outside ``[0, 1]``, e.g. slopes).
    plugin : str, optional
        The plugin named in errors.

    Returns
    -------
    mi.Texture
        The texture.

    Raises
    ------
    PluginParameterError
        When ``check`` rejects the float, or the parameter is a string or a boolean.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.properties import finite, positive, texture
    >>> props = mi.Properties("mf_microfacet")
    >>> props["mean_slope_u"], props["alpha"] = -0.5, float("nan")
    >>> texture(props, "mean_slope_u", 0.0, finite, unbounded=True).mean()
    -0.5
    >>> texture(props, "rho", 0.0).mean()            # absent: the default
    0.0
    >>> texture(props, "alpha", 0.1, positive)
    Traceback (most recent call last):
    ...
    microfacet.mitsuba.PluginParameterError: mf_microfacet: parameter 'alpha' must be a finite number > 0, got nan
    """
    if is_float(props, name) and check is not None:
        msg = check(float(props[name]))
        if msg:
            raise parameter_error(name, f"{msg}, got {float(props[name])!r}", plugin)
    if name in props and props.type(name) in (mi.Properties.Type.String, mi.Properties.Type.Bool):
        raise parameter_error(name, f"must be a float or a texture, got {props.as_string(name)!r}", plugin)
    if unbounded:
        return props.get_unbounded_texture(name, default)
    return props.get_texture(name, default)


def positive(v):
    """The check of :func:`texture` for a finite number > 0.

    Parameters
    ----------
    v : float
        The value.

    Returns
    -------
    str or None
        The error message, or ``None`` for a good value.

    Examples
    --------
    >>> from microfacet.mitsuba.properties import positive
    >>> positive(0.2), positive(0.0)
    (None, 'must be a finite number > 0')
    """
    return None if (math.isfinite(v) and v > 0) else "must be a finite number > 0"


def finite(v):
    """The check of :func:`texture` for a finite number.

    Parameters
    ----------
    v : float
        The value.

    Returns
    -------
    str or None
        The error message, or ``None`` for a good value.

    Examples
    --------
    >>> from microfacet.mitsuba.properties import finite
    >>> finite(-3.0), finite(float("inf"))
    (None, 'must be finite')
    """
    return None if math.isfinite(v) else "must be finite"


def correlation(v):
    """The check of :func:`texture` for a correlation in ``(-1, 1)``.

    Parameters
    ----------
    v : float
        The value.

    Returns
    -------
    str or None
        The error message, or ``None`` for a good value.

    Examples
    --------
    >>> from microfacet.mitsuba.properties import correlation
    >>> correlation(-0.5), correlation(1.0)
    (None, 'must lie in (-1, 1)')
    """
    return None if (math.isfinite(v) and abs(v) < 1) else "must lie in (-1, 1)"


def choice(props, name: str, default: str, choices, plugin: str = DEFAULT_PLUGIN) -> str:
    """Parameter ``name`` as one of ``choices`` (case-insensitive, returned lower-case).

    Parameters
    ----------
    props : mi.Properties
        The plugin's parameters.
    name : str
        The parameter.
    default : str
        Its value when absent.
    choices : sequence of str
        The lower-case names allowed.
    plugin : str, optional
        The plugin named in errors.

    Returns
    -------
    str
        The lower-case choice.

    Raises
    ------
    PluginParameterError
        For another value.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.properties import choice
    >>> props = mi.Properties("mf_microfacet")
    >>> props["distribution"] = "GGX"
    >>> choice(props, "distribution", "beckmann", ("beckmann", "ggx"))
    'ggx'
    >>> choice(props, "gaf", "smith", ("smith", "vgroove", "normal_map"))
    'smith'
    """
    value = props.get(name, default) if name in props else default
    if not isinstance(value, str) or value.lower() not in choices:
        raise parameter_error(name, f"must be one of {', '.join(choices)}, got {value!r}", plugin)
    return value.lower()


def flag(props, name: str, default: bool, plugin: str = DEFAULT_PLUGIN) -> bool:
    """Parameter ``name`` as a boolean, ``default`` if absent.

    Parameters
    ----------
    props : mi.Properties
        The plugin's parameters.
    name : str
        The parameter.
    default : bool
        Its value when absent.
    plugin : str, optional
        The plugin named in errors.

    Returns
    -------
    bool

    Raises
    ------
    PluginParameterError
        When the parameter is not a boolean.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.properties import flag
    >>> props = mi.Properties("mf_microfacet")
    >>> props["shadowing"], props["separable"] = False, 1.0
    >>> flag(props, "shadowing", True)
    False
    >>> flag(props, "separable", False)
    Traceback (most recent call last):
    ...
    microfacet.mitsuba.PluginParameterError: mf_microfacet: parameter 'separable' must be true or false, got '1'
    """
    if name not in props:
        return default
    if props.type(name) != mi.Properties.Type.Bool:
        raise parameter_error(name, f"must be true or false, got {props.as_string(name)!r}", plugin)
    return bool(props[name])
