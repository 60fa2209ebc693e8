"""Reading a Mitsuba plugin's parameters (``mi.Properties``), checked, for every plugin of
:mod:`microfacet.mitsuba` (``mf_microfacet``, ``mf_fitted``, ``mf_leadr``, ``mf_glints``).

A bad parameter raises :class:`~microfacet.mitsuba.PluginParameterError`, one line naming
the plugin and the parameter: ``mf_microfacet: parameter 'alpha_u' must be a finite number >
0, got -1.0`` (:func:`parameter_error`). :func:`texture` reads a float or a texture (a float
checked by a ``check`` such as :func:`positive`), :func:`choice` one of some names,
:func:`flag` a boolean.

Example (in a plugin's ``__init__(self, props)``)::

    alpha = texture(props, "alpha", 0.1, check=positive, plugin="mf_microfacet")
    shadowing = flag(props, "shadowing", True, plugin="mf_microfacet")
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
    """The error of parameter ``name`` of ``plugin``: ``"<plugin>: parameter '<name>' <message>"``."""
    return PluginParameterError(f"{plugin}: parameter '{name}' {message}")


def is_float(props, name: str) -> bool:
    """Whether ``props`` holds ``name`` as a number (float or integer)."""
    return name in props and props.type(name) in (mi.Properties.Type.Float, mi.Properties.Type.Integer)


def texture(props, name: str, default: float, check=None, unbounded: bool = False, plugin: str = DEFAULT_PLUGIN):
    """``name`` as a texture (a float becomes a uniform one); ``check(value)`` returns an
    error message for a bad float, or None."""
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
    """The check of :func:`texture` for a finite number > 0."""
    return None if (math.isfinite(v) and v > 0) else "must be a finite number > 0"


def finite(v):
    """The check of :func:`texture` for a finite number."""
    return None if math.isfinite(v) else "must be finite"


def correlation(v):
    """The check of :func:`texture` for a correlation in ``(-1, 1)``."""
    return None if (math.isfinite(v) and abs(v) < 1) else "must lie in (-1, 1)"


def choice(props, name: str, default: str, choices, plugin: str = DEFAULT_PLUGIN) -> str:
    """``name`` as one of ``choices`` (case-insensitive, returned lower-case), ``default`` if absent."""
    value = props.get(name, default) if name in props else default
    if not isinstance(value, str) or value.lower() not in choices:
        raise parameter_error(name, f"must be one of {', '.join(choices)}, got {value!r}", plugin)
    return value.lower()


def flag(props, name: str, default: bool, plugin: str = DEFAULT_PLUGIN) -> bool:
    """``name`` as a boolean, ``default`` if absent."""
    if name not in props:
        return default
    if props.type(name) != mi.Properties.Type.Bool:
        raise parameter_error(name, f"must be true or false, got {props.as_string(name)!r}", plugin)
    return bool(props[name])
