"""Microfacet Fresnel terms ``F(cos theta_d)`` in Dr.Jit (thesis Sec. 2.1, Table 2.I): the
Mitsuba twins of :mod:`microfacet.fresnel`, applied per spectral channel.

Examples
--------
Each term takes Dr.Jit values or Python floats (the scalar variants):

>>> import mitsuba as mi
>>> mi.set_variant("scalar_rgb")
>>> from microfacet.mitsuba import fresnel
>>> round(fresnel.dielectric(1.0, 1.5), 4), round(fresnel.schlick(1.0, 0.04), 4)
(0.04, 0.04)
"""
from __future__ import annotations

import drjit as dr

__all__ = ["conductor", "dielectric", "schlick", "f82_tint"]


def conductor(c, eta, k):
    """Unpolarized conductor reflectance of ``eta + i k`` in real arithmetic.

    As :func:`microfacet.fresnel.conductor_reflectance` (Table 2.I):
    ``R_s = (|n t|^2 + c^2 - 2 a c) / (|n t|^2 + c^2 + 2 a c)``,
    ``R_p = R_s (|n t|^2 c^2 + s^4 - 2 a c s^2) / (|n t|^2 c^2 + s^4 + 2 a c s^2)``,
    ``F = (R_s + R_p) / 2`` with ``s^2 = 1 - c^2``.

    Parameters
    ----------
    c : Float
        ``cos theta_d``, clamped into ``[0, 1]``.
    eta, k : Float or Spectrum
        Real and imaginary parts of the conductor's index.

    Returns
    -------
    Float or Spectrum
        ``F(c)``.

    Examples
    --------
    At normal incidence ``F = ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2)``:

    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.fresnel import conductor
    >>> round(conductor(1.0, 0.2, 3.0), 4), round((0.8**2 + 9) / (1.2**2 + 9), 4)
    (0.9234, 0.9234)
    """
    c = dr.clip(c, 0.0, 1.0)
    c2 = c * c
    s2 = 1.0 - c2
    t1 = eta * eta - k * k - s2
    a2b2 = dr.sqrt(t1 * t1 + 4.0 * eta * eta * k * k)
    ac2 = 2.0 * c * dr.safe_sqrt(0.5 * (a2b2 + t1))
    rs = (a2b2 + c2 - ac2) / (a2b2 + c2 + ac2)
    t3, t4 = a2b2 * c2 + s2 * s2, ac2 * s2
    return 0.5 * (rs + rs * (t3 - t4) / (t3 + t4))


def dielectric(c, eta):
    """Unpolarized dielectric reflectance of a real index (Table 2.I).

    As :class:`microfacet.fresnel.Dielectric`:
    ``F = 1/2 (g-c)^2/(g+c)^2 [1 + (c(g+c)-1)^2/(c(g-c)+1)^2]``, ``g^2 = eta^2 + c^2 - 1``;
    total internal reflection (``g^2 < 0``) gives 1.

    Parameters
    ----------
    c : Float
        ``cos theta_d``, clamped into ``[0, 1]``.
    eta : Float or Spectrum
        Relative index ``int_ior / ext_ior``.

    Returns
    -------
    Float or Spectrum
        ``F(c)``.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.fresnel import dielectric
    >>> round(dielectric(1.0, 1.5), 4), round(dielectric(0.0, 1.5), 4), dielectric(0.5, 1 / 1.5)
    (0.04, 1.0, 1.0)
    """
    c = dr.clip(c, 0.0, 1.0)
    g2 = eta * eta + c * c - 1.0
    g = dr.safe_sqrt(g2)
    a = (g - c) / dr.maximum(g + c, 1e-30)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    f = 0.5 * a * a * (1.0 + b * b)
    return dr.select((g2 >= 0.0) & dr.isfinite(f), f, 1.0)


def schlick(c, f0, f90=1.0):
    """Schlick's approximation with a grazing value, ``F = F0 + (F90 - F0)(1 - c)^5``.

    Schlick 1994 (Table 2.I for ``F90 = 1``), as :class:`microfacet.fresnel.Schlick`.

    Parameters
    ----------
    c : Float
        ``cos theta_d``, clamped into ``[0, 1]``.
    f0 : Float or Spectrum
        Reflectance at normal incidence.
    f90 : Float or Spectrum, optional
        Reflectance at grazing incidence (default 1).

    Returns
    -------
    Float or Spectrum
        ``F(c)``.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.fresnel import schlick
    >>> round(schlick(0.5, 0.04), 5), round(0.04 + 0.96 * 0.5**5, 5), schlick(0.0, 0.04, 0.8)
    (0.07, 0.07, 0.8)
    """
    m = 1.0 - dr.clip(c, 0.0, 1.0)
    m2 = m * m
    return f0 + (f90 - f0) * (m2 * m2 * m)


#: ``mu-bar = 1/7`` of the F82-tint term (:data:`microfacet.fresnel.F82_COS`)
F82_COS = 1.0 / 7.0


def f82_tint(c, f0, f82):
    """The F82-tint metal Fresnel term (Hoffman 2019; Kutz et al. 2021; OpenPBR's metal).

    As :class:`microfacet.fresnel.F82Tint`: ``F = F_S(c) - b c (1 - c)^6``,
    ``b = (1 - f82) F_S(1/7) / ((1/7)(6/7)^6)``, ``F_S`` Schlick's term of ``f0``, clamped to
    ``[0, 1]``; ``F(1/7) = f82 F_S(1/7)``.

    Parameters
    ----------
    c : Float
        ``cos theta_d``, clamped into ``[0, 1]``.
    f0 : Float or Spectrum
        Reflectance at normal incidence.
    f82 : Float or Spectrum
        The tint: the ratio of ``F`` to Schlick's term at ``cos theta_d = 1/7`` (about 82 degrees).

    Returns
    -------
    Float or Spectrum
        ``F(c)``.

    Examples
    --------
    >>> import mitsuba as mi
    >>> mi.set_variant("scalar_rgb")
    >>> from microfacet.mitsuba.fresnel import f82_tint, schlick
    >>> round(f82_tint(1.0, 0.9, 0.7), 4), round(f82_tint(1 / 7, 0.9, 0.7) / schlick(1 / 7, 0.9), 4)
    (0.9, 0.7)
    """
    c = dr.clip(c, 0.0, 1.0)
    m = 1.0 - c
    m5 = (m * m) * (m * m) * m
    mu_m = 1.0 - F82_COS
    b = (1.0 - f82) * (f0 + (1.0 - f0) * mu_m**5) / (F82_COS * mu_m**6)
    return dr.clip(f0 + (1.0 - f0) * m5 - b * (c * m5 * m), 0.0, 1.0)
