"""Microfacet Fresnel terms ``F(theta_d)`` (thesis Sec. 2.1, Table 2.I).

Every term maps ``cos(theta_d)`` of shape ``(...)`` to RGB reflectance ``(..., 3)``, and
describes itself to the compiled kernels by :meth:`Fresnel.kernel_params` (a
:class:`microfacet.params.FresnelParams` record; ``None`` for terms the kernels do not
compute, which then take the NumPy path).
"""
from __future__ import annotations

import functools

import numpy as np

from . import kernels
from .params import CONDUCTOR, DIELECTRIC, IDEAL, SCHLICK, TABULATED, FresnelParams, read_only

__all__ = ["Fresnel", "Ideal", "Dielectric", "Schlick", "F82Tint", "Conductor", "Tabulated"]


def _rgb(value, name: str) -> np.ndarray:
    """A scalar or an RGB triple as a ``(3,)`` float64 array, validated finite."""
    v = np.broadcast_to(np.asarray(value, dtype=np.float64), (3,)).copy()
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return v


def _unit_rgb(value, name: str) -> np.ndarray:
    """:func:`_rgb` of a reflectance, validated in ``[0, 1]``."""
    v = _rgb(value, name)
    if np.any((v < 0) | (v > 1)):
        raise ValueError(f"{name} must lie in [0, 1], got {value!r}")
    return v


def _cos(cos_theta_d) -> np.ndarray:
    return np.clip(np.asarray(cos_theta_d, dtype=np.float64), 0.0, 1.0)[..., None]


class Fresnel:
    """A Fresnel term: ``F(cos theta_d) -> RGB`` (Listing 2.3).

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.fresnel import Dielectric, Fresnel
    >>> f = Dielectric(1.5)                     # every Fresnel term maps cos(theta_d) to RGB
    >>> isinstance(f, Fresnel), f(np.array([1.0, 0.0])).round(4)
    (True, array([[0.04, 0.04, 0.04],
           [1.  , 1.  , 1.  ]]))
    """

    def __call__(self, cos_theta_d) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={np.round(v, 4).tolist()}" for k, v in vars(self).items())
        return f"{type(self).__name__}({args})"

    def kernel_params(self, dtype=np.float64) -> FresnelParams | None:
        """This term's record for the compiled kernels (:class:`microfacet.params.FresnelParams`,
        ``fp`` as ``dtype``), or ``None`` where they do not compute it: this base class, and
        subclasses of the terms below (which may change the formula). Example:
        ``Conductor.metal("Cu").kernel_params().kind == microfacet.params.CONDUCTOR``.

        Parameters
        ----------
        dtype : dtype
            Type of ``fp``.

        Returns
        -------
        FresnelParams or None
            The record, or None.
        """
        return None


class Ideal(Fresnel):
    """Ideal mirror microfacets, ``F = 1`` (Eq. 2.3).

    Examples
    --------
    >>> import numpy as np
    >>> Ideal()(np.array([1.0, 0.5, 0.0]))
    array([[1., 1., 1.],
           [1., 1., 1.],
           [1., 1., 1.]])
    """

    def __call__(self, cos_theta_d) -> np.ndarray:
        return np.ones(np.shape(cos_theta_d) + (3,))

    def kernel_params(self, dtype=np.float64) -> FresnelParams | None:
        return FresnelParams.analytic(IDEAL, dtype) if type(self) is Ideal else None


class Dielectric(Fresnel):
    """Unpolarized Fresnel reflectance of a dielectric of real index ``eta`` (Table 2.I).

    ``F = 1/2 (g-c)^2/(g+c)^2 [1 + (c(g+c)-1)^2/(c(g-c)+1)^2]`` with
    ``c = cos theta_d`` and ``g^2 = eta^2 + c^2 - 1``; total internal reflection
    (``g^2 < 0``, possible for ``eta < 1``) gives ``F = 1``.

    Parameters
    ----------
    eta : float or (3,) array_like
        Relative index of refraction (``> 0``).

    Examples
    --------
    >>> from microfacet.fresnel import Dielectric
    >>> Dielectric(1.5)([1.0, 0.0]).round(4)       # 0.04 at normal incidence, 1 at grazing
    array([[0.04, 0.04, 0.04],
           [1.  , 1.  , 1.  ]])
    """

    def __init__(self, eta=1.5):
        self.eta = _rgb(eta, "eta")
        if np.any(self.eta <= 0):
            raise ValueError(f"eta must be > 0, got {eta!r}")

    def __call__(self, cos_theta_d) -> np.ndarray:
        c = _cos(cos_theta_d)
        if self.eta[0] == self.eta[1] == self.eta[2]:      # grey: one channel, repeated
            return np.repeat(self._reflectance(self.eta[:1], c), 3, axis=-1)
        return self._reflectance(self.eta, c)

    @staticmethod
    def _reflectance(eta: np.ndarray, c: np.ndarray) -> np.ndarray:
        g2 = eta**2 + c * c - 1.0
        g = np.sqrt(np.maximum(g2, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            a = (g - c) / (g + c)
            b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
            f = 0.5 * a * a * (1.0 + b * b)
        return np.where(g2 < 0.0, 1.0, np.where(np.isfinite(f), f, 1.0))


    def kernel_params(self, dtype=np.float64) -> FresnelParams | None:
        return FresnelParams.analytic(DIELECTRIC, dtype, self.eta) if type(self) is Dielectric else None


class Schlick(Fresnel):
    """Schlick's approximation with a grazing value, ``F = F0 + (F90 - F0)(1 - c)^5``
    (Schlick 1994, "An inexpensive BRDF model for physically-based rendering"; Table 2.I for
    ``F90 = 1``; a free grazing value as in OpenPBR's ``specular_color`` of dielectrics).

    ``f0`` (normal incidence) and ``f90`` (grazing, default 1) are scalars or RGB triples in
    ``[0, 1]``; ``F`` lies between them, monotone in ``c``. As an approximation of
    :class:`Dielectric` (``f0`` from ``eta``, ``f90 = 1``) it errs by at most 0.036 for
    ``eta = 1.5``, at 85 degrees.

    Parameters
    ----------
    f0 : float or (3,) array_like
        Reflectance at normal incidence, ``[0, 1]``.
    f90 : float or (3,) array_like
        Reflectance at grazing incidence, ``[0, 1]``.

    Examples
    --------
    >>> from microfacet.fresnel import Schlick
    >>> Schlick(0.04)(1.0).round(4)
    array([0.04, 0.04, 0.04])
    >>> Schlick([0.9, 0.6, 0.5], f90=0.8)(0.0).round(4)
    array([0.8, 0.8, 0.8])
    """

    def __init__(self, f0=0.04, f90=1.0):
        self.f0 = _unit_rgb(f0, "f0")
        self.f90 = _unit_rgb(f90, "f90")

    @classmethod
    def from_eta(cls, eta) -> "Schlick":
        """Schlick term with ``F0 = (eta - 1)^2 / (eta + 1)^2`` (Table 2.I).

        Parameters
        ----------
        eta : float or (3,) array_like
            Relative index of refraction.

        Returns
        -------
        Schlick
            The term (``f90 = 1``).
        """
        eta = _rgb(eta, "eta")
        return cls(((eta - 1.0) / (eta + 1.0)) ** 2)

    def __call__(self, cos_theta_d) -> np.ndarray:
        m = 1.0 - np.clip(np.asarray(cos_theta_d, dtype=np.float64), 0.0, 1.0)
        m2 = m * m
        return self.f0 + (self.f90 - self.f0) * (m2 * m2 * m)[..., None]

    def kernel_params(self, dtype=np.float64) -> FresnelParams | None:
        """The record: ``f0`` (row 0) and ``f90`` (row 1).

        Parameters
        ----------
        dtype : dtype
            Type of ``fp``.

        Returns
        -------
        FresnelParams or None
            The record (None for a subclass).
        """
        return FresnelParams.analytic(SCHLICK, dtype, self.f0, self.f90) if type(self) is Schlick else None


#: ``mu-bar = 1/7`` of :class:`F82Tint`: the cosine (~81.8 degrees) where ``f82`` tints
#: Schlick's curve, and where ``mu (1 - mu)^6`` peaks.
F82_COS = 1.0 / 7.0


class F82Tint(Fresnel):
    """The F82-tint metal Fresnel term of Hoffman 2019 ("Fresnel equations considered
    harmful", EGSR) in the notation of Kutz et al. 2021 ("Novel aspects of the Adobe
    Standard Material"), OpenPBR Surface's metal (Andersson et al. 2024, Sec. "Metal"):

    ``F(c) = F_S(c) - b c (1 - c)^6``,  ``b = (1 - f82) F_S(mu) / (mu (1 - mu)^6)``,

    with ``F_S(c) = f0 + (1 - f0)(1 - c)^5`` (Schlick) and ``mu = 1/7`` (:data:`F82_COS`),
    so that ``F(1/7) = f82 F_S(1/7)``: ``f0`` is the reflectance at normal incidence,
    ``f82`` (RGB in ``[0, 1]``) tints it near 82 degrees, where real metals dip below
    Schlick's curve; ``f82 = 1`` is Schlick's term, ``F(0) = 1`` always. The value is
    clamped to ``[0, 1]`` (for a small ``f0`` with a low tint, e.g. ``f0 = 0, f82 = 0``,
    the correction exceeds Schlick's term in mid angles). :meth:`from_conductor` matches a
    conductor at ``c = 1`` and ``c = 1/7``; for the RGB indices of
    :attr:`Conductor.METALS` it then errs by at most 0.035 over all angles, where Schlick's
    term through the same ``f0`` errs by up to 0.13 (aluminium; tests).

    Parameters
    ----------
    f0 : float or (3,) array_like
        Reflectance at normal incidence, ``[0, 1]``.
    f82 : float or (3,) array_like
        Tint at ``cos theta_d = 1/7``, ``[0, 1]``; 1 is Schlick's term.

    Examples
    --------
    >>> import numpy as np
    >>> f = F82Tint([0.95, 0.64, 0.54], [0.9, 0.8, 0.8])
    >>> f(np.array([1.0, 1 / 7])).round(4)     # f0 at normal incidence, tinted near 82 degrees
    array([[0.95  , 0.64  , 0.54  ],
           [0.8758, 0.6452, 0.6023]])
    >>> gold = Conductor.metal("Au")
    >>> F82Tint.from_conductor(gold.eta, gold.k).f0.round(3)
    array([0.967, 0.803, 0.324])
    """

    def __init__(self, f0=(0.95, 0.64, 0.54), f82=1.0):
        self.f0 = _unit_rgb(f0, "f0")
        self.f82 = _unit_rgb(f82, "f82")

    @classmethod
    def from_conductor(cls, eta, k) -> "F82Tint":
        """The F82-tint term through the conductor ``eta + i k`` (:class:`Conductor`) at
        normal incidence and at ``c = 1/7`` (Hoffman 2019, Sec. 4): ``f0 = F(1)``,
        ``f82 = F(1/7) / F_S(1/7)`` (clipped to ``[0, 1]``).

        Parameters
        ----------
        eta, k : float or (3,) array_like
            Complex index of refraction per RGB channel.

        Returns
        -------
        F82Tint
            The matched term.
        """
        cond = Conductor(eta, k)
        f0 = cond(1.0)
        schlick = f0 + (1.0 - f0) * (1.0 - F82_COS) ** 5
        return cls(f0, np.clip(cond(F82_COS) / schlick, 0.0, 1.0))

    @property
    def b(self) -> np.ndarray:
        """The correction's coefficient ``b = (1 - f82) F_S(1/7) / ((1/7)(6/7)^6)``, RGB."""
        mu = F82_COS
        m = 1.0 - mu
        schlick = self.f0 + (1.0 - self.f0) * m**5
        return (1.0 - self.f82) * schlick / (mu * m**6)

    def __call__(self, cos_theta_d) -> np.ndarray:
        c = np.clip(np.asarray(cos_theta_d, dtype=np.float64), 0.0, 1.0)
        m = 1.0 - c
        m5 = (m * m) * (m * m) * m
        f = self.f0 + (1.0 - self.f0) * m5[..., None] - self.b * (c * m5 * m)[..., None]
        return np.clip(f, 0.0, 1.0)


class Conductor(Fresnel):
    """Unpolarized Fresnel reflectance of a conductor of complex index ``eta + i k``.

    Per RGB channel, ``F = (|r_s|^2 + |r_p|^2) / 2`` for the complex Fresnel amplitudes
    ``r_s = (c - n t)/(c + n t)``, ``r_p = (n c - t)/(n c + t)``, ``n = eta + i k``,
    ``t = sqrt(1 - (1 - c^2)/n^2)``, evaluated in real arithmetic:
    ``a^2 + b^2 = sqrt((eta^2 - k^2 - s^2)^2 + 4 eta^2 k^2)``, ``a^2 = (a^2 + b^2 + eta^2 - k^2 - s^2)/2``,
    ``R_s = (a^2 + b^2 + c^2 - 2ac)/(a^2 + b^2 + c^2 + 2ac)`` and
    ``R_p = R_s ((a^2 + b^2) c^2 + s^4 - 2 a c s^2)/((a^2 + b^2) c^2 + s^4 + 2 a c s^2)``,
    ``s^2 = 1 - c^2``. With ``k = 0`` it is :class:`Dielectric`.

    Parameters
    ----------
    eta, k : float or (3,) array_like
        Real and imaginary parts of the index per RGB channel.

    Examples
    --------
    >>> from microfacet.fresnel import Conductor, Dielectric
    >>> gold = Conductor.metal("Au")
    >>> bool(gold(1.0)[0] > gold(1.0)[2])                # reddish at normal incidence
    True
    >>> bool(abs(Conductor(1.5, 0.0)(0.5) - Dielectric(1.5)(0.5)).max() < 1e-12)
    True
    """

    #: Approximate RGB complex indices (R ~ 650 nm, G ~ 550 nm, B ~ 450 nm) of common metals.
    METALS = {
        "Au": ((0.143, 0.374, 1.442), (3.983, 2.385, 1.603)),
        "Ag": ((0.155, 0.117, 0.138), (4.828, 3.122, 2.147)),
        "Cu": ((0.200, 0.924, 1.102), (3.912, 2.452, 2.142)),
        "Al": ((1.657, 0.880, 0.521), (9.224, 6.270, 4.837)),
    }

    def __init__(self, eta=(0.143, 0.374, 1.442), k=(3.983, 2.385, 1.603)):
        self.eta = _rgb(eta, "eta")
        self.k = _rgb(k, "k")
        if np.any(self.eta <= 0) or np.any(self.k < 0):
            raise ValueError(f"need eta > 0 and k >= 0, got eta={eta!r}, k={k!r}")

    @classmethod
    def metal(cls, name: str) -> "Conductor":
        """Conductor from :attr:`METALS` (``"Au"``, ``"Ag"``, ``"Cu"``, ``"Al"``).

        Parameters
        ----------
        name : str
            A key of :attr:`METALS`.

        Returns
        -------
        Conductor
            The metal's term.
        """
        try:
            return cls(*cls.METALS[name])
        except KeyError:
            raise ValueError(f"unknown metal {name!r}; known: {sorted(cls.METALS)}") from None

    def __call__(self, cos_theta_d) -> np.ndarray:
        c = np.clip(np.asarray(cos_theta_d, dtype=np.float64), 0.0, 1.0)
        f = _conductor_compiled()
        if f is None:
            return np.stack([conductor_reflectance(c, eta, k) for eta, k in zip(self.eta, self.k)], axis=-1)
        flat = np.ascontiguousarray(c).reshape(-1)
        return np.stack([f(flat, eta, k).reshape(c.shape) for eta, k in zip(self.eta, self.k)], axis=-1)

    def kernel_params(self, dtype=np.float64) -> FresnelParams | None:
        return FresnelParams.analytic(CONDUCTOR, dtype, self.eta, self.k) if type(self) is Conductor else None


def conductor_reflectance(c, eta, k):
    """One channel of :class:`Conductor` at ``c = cos theta_d`` (arrays or scalars; the
    same function is compiled by Numba when available)."""
    c2 = c * c
    s2 = 1.0 - c2
    t1 = eta * eta - k * k - s2
    a2b2 = np.sqrt(t1 * t1 + 4.0 * eta * eta * k * k)
    ac2 = 2.0 * c * np.sqrt(np.maximum(0.5 * (a2b2 + t1), 0.0))
    rs = (a2b2 + c2 - ac2) / (a2b2 + c2 + ac2)
    t3, t4 = a2b2 * c2 + s2 * s2, ac2 * s2
    return 0.5 * (rs + rs * (t3 - t4) / (t3 + t4))


@functools.cache
def _conductor_compiled():
    """:func:`conductor_reflectance` compiled by Numba on first use (1-D arrays), or ``None``."""
    return kernels.compiled(conductor_reflectance)


class Tabulated(Fresnel):
    """Piecewise-linear ``cos theta_d -> RGB`` table, clamped at its ends.

    ``cos_theta_d`` is an increasing ``(N,)`` grid and ``values`` its ``(N, 3)`` RGB
    samples (e.g. the Fresnel term extracted by the fitting of Ch. 4, Eq. 4.11).

    Parameters
    ----------
    cos_theta_d : (N,) array_like
        Increasing grid of ``cos theta_d``.
    values : (N, 3) array_like
        RGB values at the grid.

    Examples
    --------
    >>> from microfacet.fresnel import Tabulated
    >>> table = Tabulated([0.0, 1.0], [[1.0, 1.0, 1.0], [0.2, 0.4, 0.6]])
    >>> table(0.5).round(4)
    array([0.6, 0.7, 0.8])
    """

    def __init__(self, cos_theta_d, values):
        self.cos_theta_d = np.asarray(cos_theta_d, dtype=np.float64).ravel()
        values = np.asarray(values, dtype=np.float64)
        n = len(self.cos_theta_d)
        if n < 2 or values.shape not in ((n,), (n, 1), (n, 3)):
            raise ValueError(f"Tabulated needs >= 2 samples and values of shape ({n},) or ({n}, 3), "
                             f"got {values.shape}")
        self.values = np.repeat(values.reshape(n, -1), 3 // values.reshape(n, -1).shape[1], axis=1)
        if np.any(np.diff(self.cos_theta_d) <= 0):
            raise ValueError("Tabulated cos_theta_d must be strictly increasing")
        if not (np.all(np.isfinite(self.values)) and np.all(np.isfinite(self.cos_theta_d))):
            raise ValueError("Tabulated samples must be finite")

    def __call__(self, cos_theta_d) -> np.ndarray:
        c = np.asarray(cos_theta_d, dtype=np.float64)
        return np.stack([np.interp(c, self.cos_theta_d, v) for v in self.values.T], axis=-1)

    def kernel_params(self, dtype=np.float64) -> FresnelParams | None:
        """The table, read by the kernels in float64 whatever ``dtype`` (as ``np.interp``).

        Parameters
        ----------
        dtype : dtype
            Ignored (the table stays float64).

        Returns
        -------
        FresnelParams or None
            The record (None for a subclass).
        """
        if type(self) is not Tabulated:
            return None
        return FresnelParams(TABULATED, read_only(np.zeros((2, 3), dtype)),
                             read_only(np.ascontiguousarray(self.cos_theta_d)), read_only(np.ascontiguousarray(self.values)))
