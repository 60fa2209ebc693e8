"""Frozen parameter records of the compiled Smith microfacet kernels.

A :class:`~microfacet.brdf.MicrofacetBRDF` with a Smith GAF, a scalar Beckmann or GGX
distribution and a Fresnel term the kernels know is described, for the compiled backend,
by one :class:`SmithParams` record, built once (:func:`smith_params`, from
``MicrofacetBRDF.params``) and passed whole: into the Numba kernels of
:mod:`microfacet._numba_kernels` as a named tuple (Numba types it as a tuple and reads its
fields as ``p.ax``, ``p.fresnel.fp``; no copy, no loose arguments), as pbrt-v4's
``TrowbridgeReitzDistribution`` and ``ConductorBxDF`` carry theirs. The record holds:

* ``kind``: :data:`BECKMANN` or :data:`GGX` (it selects the compiled kernel, in which the
  kind is a compile-time constant);
* ``ax``, ``ay``, ``rho``, ``xn``, ``yn``: roughness, correlation and mean slope
  (Dupuy 2015, Eq. 3.2-3.4) as scalars of the BRDF's arithmetic type;
* ``shadowing``: whether ``G`` has the shadowing term ``Lambda(i)`` (Eq. 2.13);
* ``fresnel``: a :class:`FresnelParams` record, made by the Fresnel term itself
  (:meth:`microfacet.fresnel.Fresnel.kernel_params`).

A new model parameter is a new field here and its use in each backend's formula; a new
Fresnel term a new kind code here, its :meth:`~microfacet.fresnel.Fresnel.kernel_params`
and its formula in ``_numba_kernels._fresnel_block``.

Example::

    >>> import microfacet as mf
    >>> p = mf.MicrofacetBRDF(mf.GGX(alpha=0.3)).params
    >>> (p.kind == GGX, float(p.ax), p.shadowing, p.fresnel.kind == IDEAL)
    (True, 0.3, True, True)
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from . import distributions

__all__ = ["BECKMANN", "GGX", "IDEAL", "SCHLICK", "DIELECTRIC", "CONDUCTOR", "TABULATED",
           "FresnelParams", "SmithParams", "smith_params", "fresnel_params", "read_only"]

#: Distribution kinds of :class:`SmithParams` (the kernels are compiled per kind).
BECKMANN = 0
GGX = 1
#: Fresnel kinds of :class:`FresnelParams` (``_numba_kernels._fresnel_block`` branches on them).
IDEAL = 0
SCHLICK = 1
DIELECTRIC = 2
CONDUCTOR = 3
TABULATED = 4


def read_only(a: np.ndarray) -> np.ndarray:
    """A read-only view of ``a``: the kernels read their array parameters as read-only arrays,
    whether the caller's are writeable or not (one compiled version instead of two: Numba
    compiles per read-only flag).

    Parameters
    ----------
    a : ndarray
        Any array.

    Returns
    -------
    ndarray
        A non-writeable view.

    Examples
    --------
    >>> import numpy as np
    >>> v = read_only(np.zeros(3))
    >>> v.flags.writeable
    False
    """
    v = a.view()
    v.flags.writeable = False
    return v


class FresnelParams(NamedTuple):
    """The Fresnel term of :class:`SmithParams`: ``kind`` (:data:`IDEAL` ... :data:`TABULATED`),
    ``fp`` ``(2, 3)`` of the kernels' arithmetic type (row 0: Schlick's ``f0`` or ``eta``, row 1:
    a conductor's ``k``), ``tx`` ``(m,)`` and ``tv`` ``(m, 3)`` float64: a tabulated term's
    ``cos theta_d`` grid and values (zeros for the analytic terms). Arrays read-only.

    Attributes
    ----------
    kind : int
        Which term (:data:`IDEAL` ... :data:`TABULATED`).
    fp : (2, 3) ndarray
        Scalar parameters of the term.
    tx : (m,) ndarray
        Tabulated ``cos theta_d`` grid.
    tv : (m, 3) ndarray
        Tabulated RGB values.

    Examples
    --------
    >>> f = FresnelParams.analytic(SCHLICK, "float64", row0=0.04)
    >>> f.kind == SCHLICK, f.fp[0].tolist(), f.tx.shape
    (True, [0.04, 0.04, 0.04], (2,))
    >>> (IDEAL, SCHLICK, DIELECTRIC, CONDUCTOR, TABULATED)     # the kind codes
    (0, 1, 2, 3, 4)
    """

    kind: int
    fp: np.ndarray
    tx: np.ndarray
    tv: np.ndarray

    @classmethod
    def analytic(cls, kind: int, dtype, row0=0.0, row1=0.0) -> "FresnelParams":
        """The record of an analytic term (no table): ``fp = [row0, row1]`` as ``dtype``.

        Parameters
        ----------
        kind : int
            :data:`IDEAL`, :data:`SCHLICK`, :data:`DIELECTRIC`, :data:`CONDUCTOR` ...
        dtype : dtype
            Type of ``fp``.
        row0, row1 : float or (3,) array_like
            ``fp``'s two rows.

        Returns
        -------
        FresnelParams
            The record.
        """
        fp = np.zeros((2, 3), dtype)
        fp[0], fp[1] = row0, row1
        return cls(kind, read_only(fp), _NO_TABLE[0], _NO_TABLE[1])


#: The table of analytic terms (unused by their formulas; a fixed type for Numba).
_NO_TABLE = (read_only(np.zeros(2)), read_only(np.zeros((2, 3))))


class SmithParams(NamedTuple):
    """Parameters of a Smith microfacet BRDF for the compiled kernels (module docstring).

    Attributes
    ----------
    kind : int
        :data:`BECKMANN` or :data:`GGX`.
    ax, ay : float
        Roughness along x and y.
    rho : float
        Slope correlation, ``(-1, 1)``.
    xn, yn : float
        Mean slope.
    shadowing : bool
        Smith shadowing on (else masking only).
    fresnel : FresnelParams
        The Fresnel term.

    Examples
    --------
    >>> import microfacet as mf
    >>> p = smith_params(mf.Beckmann(alpha_x=0.2, alpha_y=0.4))
    >>> p.kind == BECKMANN, float(p.ax), float(p.ay), float(p.rho)
    (True, 0.2, 0.4, 0.0)
    """

    kind: int
    ax: float
    ay: float
    rho: float
    xn: float
    yn: float
    shadowing: bool
    fresnel: FresnelParams


def fresnel_params(fresnel, dtype=np.float64) -> FresnelParams | None:
    """``fresnel.kernel_params(dtype)`` (:meth:`microfacet.fresnel.Fresnel.kernel_params`), or
    ``None`` for ``None``: the ideal term (``F = 1``).

    Parameters
    ----------
    fresnel : Fresnel or None
        The term; None is ``F = 1``.
    dtype : dtype
        Type of ``fp``.

    Returns
    -------
    FresnelParams or None
        The record, or None where the kernels do not compute the term.

    Examples
    --------
    >>> import microfacet as mf
    >>> fresnel_params(None).kind == IDEAL
    True
    >>> f = fresnel_params(mf.fresnel.Conductor(eta=0.2, k=3.0))
    >>> f.kind == CONDUCTOR, f.fp[:, 0].tolist()
    (True, [0.2, 3.0])
    >>> fresnel_params(mf.fresnel.Dielectric(eta=1.5)).kind == DIELECTRIC
    True
    """
    if fresnel is None:
        return FresnelParams.analytic(IDEAL, dtype)
    return fresnel.kernel_params(dtype)


def smith_params(distribution, fresnel=None, shadowing: bool = True, dtype=np.float64) -> SmithParams | None:
    """The :class:`SmithParams` of a Smith BRDF with ``distribution``, ``fresnel`` (``None``:
    ideal) and ``shadowing``, its scalars as ``dtype``; ``None`` where the kernels do not cover
    it: a distribution other than a :class:`~microfacet.distributions.Beckmann` or
    :class:`~microfacet.distributions.GGX` with scalar parameters (subclasses included: they
    may change the formulas), or a Fresnel term without a record.

    Parameters
    ----------
    distribution : SlopeDistribution
        The microfacet distribution.
    fresnel : Fresnel, optional
        The Fresnel term; None is ``F = 1``.
    shadowing : bool
        Smith shadowing on (else masking only).
    dtype : dtype
        Type of the scalars.

    Returns
    -------
    SmithParams or None
        The record, or None where the kernels do not cover the BRDF.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> smith_params(mf.GGX(alpha=0.3)).kind == GGX
    True
    >>> smith_params(mf.GGX(alpha=np.array([0.1, 0.3]))) is None     # per-direction alpha: no kernel
    True
    """
    d, t = distribution, type(distribution)
    if t not in (distributions.Beckmann, distributions.GGX) \
            or any(np.ndim(p) for p in (d.alpha_x, d.alpha_y, d.rho, d.xn, d.yn)):
        return None
    f = fresnel_params(fresnel, dtype)
    if f is None:
        return None
    F = np.dtype(dtype).type
    return SmithParams(GGX if t is distributions.GGX else BECKMANN, F(d.alpha_x), F(d.alpha_y), F(d.rho),
                       F(d.xn), F(d.yn), bool(shadowing), f)
