"""Published analytic fits of the MERL materials, as BRDFs of the library's protocol: the
references a fit of this project is compared with.

* :class:`ABC` — the ABC model of Löw, Kronander, Ynnerman & Unger 2012 ("BRDF models
  for accurate and efficient rendering of glossy surfaces", ACM TOG 31(1)), as Dupuy's
  dj_brdf evaluates it (``djb::abc``): a Lambertian term plus a microfacet lobe with the
  ABC distribution ``D = A / (1 + B (1 - cos theta_h))^C`` (per channel ``A``), an
  unpolarized dielectric Fresnel of index ``ior`` and the Cook-Torrance V-cavity
  shadowing ``G = min(1, 2 cos th_h cos th_i / (i.h), 2 cos th_h cos th_o / (o.h))``:

  ``f = kd / pi + F(ior; i.h) D G / (pi cos th_i cos th_o)``.

* :class:`SGD` — the shifted-gamma model of Bagher, Soler & Holzschuch 2012 ("Accurate
  fitting of measured reflectances using a Shifted Gamma micro-facet distribution", CGF
  31(4)), as dj_brdf evaluates it (``djb::sgd``), per channel:

  ``f = (rhoD + rhoS F D G / (cos th_i cos th_o)) / pi``, ``D = kap exp(-a) / (pi a^p
  cos^4 th_h)``, ``a = alpha + tan^2 th_h / alpha``, ``F = f0 - c f1 + (1 - c)^5 (1 - f0)``
  (``c = i.h``), ``G = g1(i) g1(o)``, ``g1(k) = clamp(1 + lambda (1 - exp(c_ max(0, th_k -
  theta0)^k)), 0, 1)``.

:func:`read_abc` and :func:`read_sgd` read the parameter tables of ``DATA/anchors`` (the data folder)
(``abc_low2012_merl.csv``, ``sgd_bagher2012_merl.csv``; columns :data:`ABC_COLUMNS`, :data:`SGD_COLUMNS`) into
``{material: BRDF}``. Neither model conserves energy by construction (``A`` and ``kap``
are free scales): their white-furnace albedo is whatever the fit made it.

Sampling: :class:`ABC` draws the half vector from its own distribution (``D cos th_h``
inverted in closed form) or a cosine-weighted direction, half and half, and returns the
mixture's density; :class:`SGD` samples the cosine-weighted hemisphere. Both are exact
importance samplers of their densities (``weight = eval_cos / pdf``).

Example
-------
>>> from microfacet.anchors import read_abc
>>> fits = read_abc("DATA/anchors/abc_low2012_merl.csv")              # doctest: +SKIP
>>> fits["nickel"].eval_cos(wi, wo)                                   # doctest: +SKIP

Examples
--------
>>> from microfacet.anchors import ABC_COLUMNS, SGD_COLUMNS
>>> ABC_COLUMNS
('kd_r', 'kd_g', 'kd_b', 'A_r', 'A_g', 'A_b', 'B', 'C', 'ior')
>>> len(SGD_COLUMNS), SGD_COLUMNS[:3]
(33, ('rhoD_r', 'rhoD_g', 'rhoD_b'))
"""
from __future__ import annotations

import csv
import os

import numpy as np

from .brdf import BRDF, uniforms, unit_directions
from .errors import MicrofacetError
from .geometry import cosine_hemisphere_pdf, reflect, spherical_to_cartesian, square_to_cosine_hemisphere

__all__ = ["ABC", "SGD", "read_abc", "read_sgd", "abc_fits", "ABC_COLUMNS", "SGD_COLUMNS"]

#: Columns of ``abc_low2012_merl.csv`` after ``material``.
ABC_COLUMNS = ("kd_r", "kd_g", "kd_b", "A_r", "A_g", "A_b", "B", "C", "ior")
_SGD_FIELDS = ("rhoD", "rhoS", "alpha", "p", "f0", "f1", "kap", "lambda", "c", "k", "theta0")
#: Columns of ``sgd_bagher2012_merl.csv`` after ``material`` (the ``error_*`` columns, the
#: paper's fit error, are read but not used).
SGD_COLUMNS = tuple(f"{f}_{c}" for f in _SGD_FIELDS for c in "rgb")


def _rgb(values, name: str) -> np.ndarray:
    try:
        v = np.broadcast_to(np.asarray(values, dtype=np.float64), (3,)).copy()
    except (ValueError, TypeError):
        raise ValueError(f"{name} must be a number or 3 RGB numbers, got {values!r}") from None
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {values!r}")
    return v


def unpolarized_fresnel(cos_d, ior) -> np.ndarray:
    """Unpolarized Fresnel reflectance of a dielectric of relative index ``ior`` at
    ``cos_d = i.h`` (Cook & Torrance 1982, Eq. in dj_brdf's ``unpolarized__eval``)."""
    c = np.clip(cos_d, 0.0, 1.0)
    g = np.sqrt(np.maximum(ior * ior + c * c - 1.0, 0.0))
    a = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = 0.5 * ((g - c) / (g + c)) ** 2 * (1.0 + a * a)
    return np.where(g + c > 0, f, 1.0)


class _Published(BRDF):
    """Common evaluation scaffold: ``f_r`` from :meth:`_f` over the upper hemisphere pairs."""

    def _pairs(self, wi, wo):
        wi, wo = np.broadcast_arrays(unit_directions(wi, "wi"), unit_directions(wo, "wo"))
        up = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        h = wi + wo
        h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
        return wi, wo, h, up

    def eval(self, wi, wo, out=None) -> np.ndarray:
        """``f_r(wi, wo)``, RGB ``(..., 3)``; 0 below either horizon.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions, local frame (z up).
        out : ndarray, optional
            Array ``(..., 3)`` to write into.

        Returns
        -------
        (..., 3) ndarray
            RGB values, per steradian.
        """
        wi, wo, h, up = self._pairs(wi, wo)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            f = self._f(wi, wo, h)
        f = np.where(up[..., None], f, 0.0)
        if out is not None:
            np.copyto(out, f)
            return out
        return f

    def eval_cos(self, wi, wo, out=None) -> np.ndarray:
        """``f_r(wi, wo) cos theta_i``, RGB ``(..., 3)``.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions, local frame (z up).
        out : ndarray, optional
            Array ``(..., 3)`` to write into.

        Returns
        -------
        (..., 3) ndarray
            RGB values.
        """
        wi = unit_directions(wi, "wi")
        f = self.eval(wi, wo) * np.maximum(wi[..., 2:3], 0.0)
        if out is not None:
            np.copyto(out, f)
            return out
        return f

    def _cosine_pdf(self, wi, wo):
        return np.where((wo[..., 2] > 0) & (wi[..., 2] > 0), cosine_hemisphere_pdf(wi), 0.0)


class ABC(_Published):
    """The ABC BRDF of Löw et al. 2012 (module docstring) for one material.

    Parameters
    ----------
    kd : float or (3,)
        Diffuse albedo (the Lambertian term is ``kd / pi``).
    A : float or (3,)
        Scale of the ABC distribution per channel.
    B, C : float
        Width and fall-off of ``D = A / (1 + B (1 - cos theta_h))^C`` (``B > 0``).
    ior : float
        Relative index of the unpolarized dielectric Fresnel term (``> 0``).
    spec_fraction : float
        Probability that :meth:`sample` draws from the lobe rather than the cosine.

    Example
    -------
    >>> import numpy as np
    >>> brdf = ABC(kd=0.1, A=50.0, B=1e4, C=0.8, ior=2.2)
    >>> w = np.array([0.0, 0.0, 1.0])
    >>> bool(brdf.eval(w, w)[0] > 0.1 / np.pi)
    True
    """

    def __init__(self, kd, A, B: float, C: float, ior: float, spec_fraction: float = 0.5):
        self.kd, self.A = _rgb(kd, "kd"), _rgb(A, "A")
        self.B, self.C, self.ior = float(B), float(C), float(ior)
        if not (self.B > 0 and np.isfinite(self.B)):
            raise ValueError(f"B must be a finite number > 0, got {B!r}")
        if not np.isfinite(self.C):
            raise ValueError(f"C must be finite, got {C!r}")
        if not (self.ior > 0 and np.isfinite(self.ior)):
            raise ValueError(f"ior must be a finite number > 0, got {ior!r}")
        if not 0.0 <= spec_fraction <= 1.0:
            raise ValueError(f"spec_fraction must lie in [0, 1], got {spec_fraction!r}")
        self.spec_fraction = float(spec_fraction) if np.any(self.A > 0) else 0.0

    def __repr__(self) -> str:
        return (f"ABC(kd={self.kd.tolist()}, A={self.A.tolist()}, B={self.B!r}, C={self.C!r}, "
                f"ior={self.ior!r})")

    def ndf(self, cos_h) -> np.ndarray:
        """``D = A / (1 + B (1 - cos theta_h))^C``, RGB ``(..., 3)`` (Löw et al. 2012, Eq. 9
        with dj_brdf's ``1 - cos theta_h``).

        Parameters
        ----------
        cos_h : array_like
            ``cos theta_h``.

        Returns
        -------
        (..., 3) ndarray
            ``D`` per RGB channel.
        """
        x = 1.0 - np.clip(np.asarray(cos_h, dtype=np.float64), -1.0, 1.0)
        return self.A / ((1.0 + self.B * x) ** self.C)[..., None]

    def _f(self, wi, wo, h):
        ih, oh, hz = np.sum(wi * h, -1), np.sum(wo * h, -1), h[..., 2]
        g = np.minimum(1.0, np.minimum(2.0 * hz * wi[..., 2] / ih, 2.0 * hz * wo[..., 2] / oh))
        g = np.where((ih > 0) & (oh > 0), np.maximum(g, 0.0), 0.0)
        spec = unpolarized_fresnel(ih, self.ior)[..., None] * self.ndf(hz) * g[..., None]
        return self.kd / np.pi + spec / (np.pi * wi[..., 2] * wo[..., 2])[..., None]

    # half-vector sampling: x = 1 - cos theta_h on [0, 1] with density (1 + B x)^-C / Z,
    # phi uniform; d omega_h = dx dphi, so p(h) = p(x) / (2 pi).
    def _log_norm(self) -> float:
        k, L = 1.0 - self.C, np.log1p(self.B)
        if abs(k * L) < 1e-10:
            return float(np.log(L / self.B))
        return float(np.log(np.expm1(k * L) / (k * self.B)))

    def _x_of_u(self, u):
        k, L = 1.0 - self.C, np.log1p(self.B)
        if abs(k * L) < 1e-10:
            return np.expm1(u * L) / self.B
        return np.expm1(np.log1p(u * np.expm1(k * L)) / k) / self.B

    def _lobe_pdf(self, wi, wo):
        """Solid-angle density of the lobe's samples ``wi`` given ``wo``."""
        h = wi + wo
        h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
        oh, x = np.sum(wo * h, -1), 1.0 - h[..., 2]
        p_h = np.exp(-self.C * np.log1p(self.B * np.clip(x, 0.0, 1.0)) - self._log_norm()) / (2.0 * np.pi)
        ok = (oh > 0) & (h[..., 2] >= 0) & (wi[..., 2] > 0) & (wo[..., 2] > 0)
        return np.where(ok, p_h / (4.0 * np.maximum(oh, 1e-300)), 0.0)

    def pdf(self, wi, wo, out=None) -> np.ndarray:
        """Density of :meth:`sample`: ``s p_lobe + (1 - s) cos theta_i / pi``.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions, local frame (z up).
        out : ndarray, optional
            Array ``(...)`` to write into.

        Returns
        -------
        (...) ndarray
            Density per steradian of ``wi``.
        """
        wi, wo = np.broadcast_arrays(unit_directions(wi, "wi"), unit_directions(wo, "wo"))
        s = self.spec_fraction
        p = (1.0 - s) * self._cosine_pdf(wi, wo)
        if s > 0:
            p = p + s * self._lobe_pdf(wi, wo)
        if out is not None:
            np.copyto(out, p)
            return out
        return p

    def sample(self, u, wo, out=None):
        """``(wi, weight, pdf)``: the lobe (probability ``spec_fraction``; half vector from
        ``D cos theta_h``, closed-form inverse) or the cosine, ``weight = eval_cos / pdf``.

        Parameters
        ----------
        u : (..., 2) array_like
            Uniform numbers in ``[0, 1]``.
        wo : (..., 3) array_like
            Unit view directions, local frame.
        out : tuple of 3 ndarray, optional
            ``(wi, weight, pdf)`` arrays to write into.

        Returns
        -------
        wi : (..., 3) ndarray
            Sampled light directions.
        weight : (..., 3) ndarray
            ``eval_cos / pdf``, RGB.
        pdf : (...) ndarray
            Density per steradian.
        """
        wo, u = unit_directions(wo, "wo"), uniforms(u)
        shape = np.broadcast_shapes(u.shape[:-1], wo.shape[:-1])
        u = np.broadcast_to(u, shape + (2,))
        wo = np.broadcast_to(wo, shape + (3,))
        s = self.spec_fraction
        lobe = u[..., 0] < s
        u0 = np.where(lobe, u[..., 0] / max(s, 1e-300), (u[..., 0] - s) / max(1.0 - s, 1e-300))
        u0 = np.clip(u0, 0.0, 1.0)
        x = self._x_of_u(u0)
        theta = np.arccos(np.clip(1.0 - x, -1.0, 1.0))
        h = spherical_to_cartesian(theta, 2.0 * np.pi * u[..., 1])
        wi_lobe = reflect(wo, h)
        wi_cos = square_to_cosine_hemisphere(np.stack([u0, u[..., 1]], -1))
        wi = np.where(lobe[..., None], wi_lobe, wi_cos)
        wi = wi / np.maximum(np.linalg.norm(wi, axis=-1, keepdims=True), 1e-300)
        pdf = self.pdf(wi, wo)
        ok = (pdf > 0) & (wi[..., 2] > 0) & (wo[..., 2] > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            weight = np.where(ok[..., None], self.eval_cos(wi, wo) / np.where(ok, pdf, 1.0)[..., None], 0.0)
        pdf = np.where(ok, pdf, 0.0)
        if out is not None:
            for o, a in zip(out, (wi, weight, pdf)):
                np.copyto(o, a)
            return out
        return wi, weight, pdf


class SGD(_Published):
    """The shifted-gamma BRDF of Bagher et al. 2012 (module docstring) for one material;
    every parameter an RGB triple (or one number for all channels), named as the columns
    of ``sgd_bagher2012_merl.csv``: ``rhoD, rhoS, alpha, p, f0, f1, kap, lam`` (the
    column ``lambda``), ``c, k, theta0`` (radians). Cosine-weighted sampling.

    Parameters
    ----------
    rhoD, rhoS : float or (3,) array_like
        Diffuse and specular albedo.
    alpha, p : float or (3,) array_like
        Width and shape of the shifted-gamma distribution.
    f0, f1 : float or (3,) array_like
        Fresnel parameters.
    kap : float or (3,) array_like
        Scale of the distribution.
    lam, c, k, theta0 : float or (3,) array_like
        Masking parameters (``theta0`` in radians).

    Example
    -------
    >>> import numpy as np
    >>> brdf = SGD(rhoD=0.05, rhoS=0.3, alpha=0.005, p=0.2, f0=1.0, f1=0.5, kap=100.0, lam=2.0,
    ...            c=1e-7, k=40.0, theta0=0.8)
    >>> w = np.array([0.0, 0.0, 1.0])
    >>> bool(brdf.eval(w, w)[0] > 0.05 / np.pi)
    True
    """

    def __init__(self, rhoD, rhoS, alpha, p, f0, f1, kap, lam, c, k, theta0):
        values = dict(rhoD=rhoD, rhoS=rhoS, alpha=alpha, p=p, f0=f0, f1=f1, kap=kap, lam=lam, c=c, k=k,
                      theta0=theta0)
        for name, v in values.items():
            setattr(self, name, _rgb(v, name))
        if not np.all(self.alpha > 0):
            raise ValueError(f"alpha must be > 0 per channel, got {alpha!r}")

    def __repr__(self) -> str:
        return "SGD(" + ", ".join(f"{n}={getattr(self, n).tolist()}" for n in
                                  ("rhoD", "rhoS", "alpha", "p", "f0", "f1", "kap", "lam", "c", "k", "theta0")) + ")"

    def ndf(self, cos_h) -> np.ndarray:
        """``D = kap exp(-a) / (pi a^p cos^4 theta_h)``, ``a = alpha + tan^2 theta_h / alpha``,
        RGB ``(..., 3)`` (Bagher et al. 2012, Eq. 6).

        Parameters
        ----------
        cos_h : array_like
            ``cos theta_h``.

        Returns
        -------
        (..., 3) ndarray
            ``D`` per RGB channel.
        """
        c2 = np.clip(np.asarray(cos_h, dtype=np.float64), 1e-12, 1.0)[..., None] ** 2
        a = self.alpha + (1.0 - c2) / c2 / self.alpha
        return self.kap * np.exp(-a) / (np.pi * a ** self.p * c2 * c2)

    def g1(self, cos_k) -> np.ndarray:
        """``clamp(1 + lambda (1 - exp(c max(0, theta_k - theta0)^k)), 0, 1)``, RGB.

        Parameters
        ----------
        cos_k : array_like
            ``cos theta_k`` of the direction.

        Returns
        -------
        (..., 3) ndarray
            Masking per RGB channel, ``[0, 1]``.
        """
        t = np.maximum(np.arccos(np.clip(np.asarray(cos_k, dtype=np.float64), -1.0, 1.0))[..., None] - self.theta0, 0.0)
        return np.clip(1.0 + self.lam * (1.0 - np.exp(self.c * t ** self.k)), 0.0, 1.0)

    def _f(self, wi, wo, h):
        ch = np.clip(np.sum(wi * h, -1), 0.0, 1.0)[..., None]
        fresnel = self.f0 - ch * self.f1 + (1.0 - ch) ** 5 * (1.0 - self.f0)
        g = self.g1(wi[..., 2]) * self.g1(wo[..., 2])
        spec = self.rhoS * fresnel * self.ndf(h[..., 2]) * g / (wi[..., 2] * wo[..., 2])[..., None]
        return (self.rhoD + spec) / np.pi

    def pdf(self, wi, wo, out=None) -> np.ndarray:
        """``cos theta_i / pi`` (0 where either direction is below the horizon).

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions, local frame (z up).
        out : ndarray, optional
            Array ``(...)`` to write into.

        Returns
        -------
        (...) ndarray
            Density per steradian of ``wi``.
        """
        wi, wo = np.broadcast_arrays(unit_directions(wi, "wi"), unit_directions(wo, "wo"))
        p = self._cosine_pdf(wi, wo)
        if out is not None:
            np.copyto(out, p)
            return out
        return p

    def sample(self, u, wo, out=None):
        """Cosine-weighted ``(wi, weight, pdf)``, ``weight = eval_cos / pdf``.

        Parameters
        ----------
        u : (..., 2) array_like
            Uniform numbers in ``[0, 1]``.
        wo : (..., 3) array_like
            Unit view directions, local frame.
        out : tuple of 3 ndarray, optional
            ``(wi, weight, pdf)`` arrays to write into.

        Returns
        -------
        wi : (..., 3) ndarray
            Sampled light directions.
        weight : (..., 3) ndarray
            ``eval_cos / pdf``, RGB.
        pdf : (...) ndarray
            Density per steradian.
        """
        wo, u = unit_directions(wo, "wo"), uniforms(u)
        shape = np.broadcast_shapes(u.shape[:-1], wo.shape[:-1])
        wi = square_to_cosine_hemisphere(np.broadcast_to(u, shape + (2,)))
        wo = np.broadcast_to(wo, shape + (3,))
        pdf = self.pdf(wi, wo)
        ok = pdf > 0
        weight = np.where(ok[..., None], self.eval_cos(wi, wo) / np.where(ok, pdf, 1.0)[..., None], 0.0)
        if out is not None:
            for o, a in zip(out, (wi, weight, pdf)):
                np.copyto(o, a)
            return out
        return wi, weight, pdf


def _read_table(csv_path, columns, name: str) -> dict[str, dict[str, float]]:
    """Rows of a parameter CSV as ``{material: {column: value}}``; ``MicrofacetError``
    naming the file on a missing column, a bad number or an empty table."""
    path = os.fspath(csv_path)
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        raise MicrofacetError(f"{path}: cannot read the {name} table ({e.strerror or e})") from None
    if not rows:
        raise MicrofacetError(f"{path}: the {name} table is empty")
    missing = [c for c in ("material",) + tuple(columns) if c not in rows[0]]
    if missing:
        raise MicrofacetError(f"{path}: not a {name} table, missing column(s) {', '.join(missing)}")
    out = {}
    for line, row in enumerate(rows, start=2):
        try:
            out[row["material"].strip()] = {c: float(row[c]) for c in columns}
        except (TypeError, ValueError):
            raise MicrofacetError(f"{path}, line {line}: a value of {row.get('material')!r} is not a number") from None
    return out


def read_abc(csv_path) -> dict[str, ABC]:
    """The ABC fits of a table with the columns of :data:`ABC_COLUMNS` (e.g.
    ``../shared/data/anchors/abc_low2012_merl.csv``, Löw et al. 2012 via dj_brdf) as
    ``{material: ABC}``, in file order. ``MicrofacetError`` naming the file if it is
    unreadable or malformed, ``ValueError`` naming the parameter if a value is invalid.

    Parameters
    ----------
    csv_path : str or os.PathLike
        The CSV table.

    Returns
    -------
    dict of str to ABC
        The fits by material name.

    Examples
    --------
    >>> import numpy as np
    >>> _ = open("abc.csv", "w").write("material," + ",".join(ABC_COLUMNS) + chr(10)
    ...                                + "grey,0.1,0.1,0.1,50,50,50,10000,0.8,2.2" + chr(10))
    >>> fits = read_abc("abc.csv")
    >>> list(fits), float(fits["grey"].eval(np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0]))[0].round(2))
    (['grey'], 2.27)
    """
    out = {}
    for material, r in _read_table(csv_path, ABC_COLUMNS, "ABC").items():
        out[material] = ABC((r["kd_r"], r["kd_g"], r["kd_b"]), (r["A_r"], r["A_g"], r["A_b"]), r["B"], r["C"], r["ior"])
    return out


#: The name of :data:`microfacet` interfaces for :func:`read_abc`.
abc_fits = read_abc


def read_sgd(csv_path) -> dict[str, SGD]:
    """The SGD fits of a table with the columns of :data:`SGD_COLUMNS` (e.g.
    ``../shared/data/anchors/sgd_bagher2012_merl.csv``, Bagher et al. 2012 via dj_brdf) as
    ``{material: SGD}``, in file order (errors as :func:`read_abc`).

    Parameters
    ----------
    csv_path : str or os.PathLike
        The CSV table.

    Returns
    -------
    dict of str to SGD
        The fits by material name.

    Examples
    --------
    >>> row = ["0.05"] * 3 + ["0.3"] * 3 + ["0.005"] * 3 + ["0.2"] * 3 + ["1"] * 3 + ["0.5"] * 3 + ["100"] * 3 + ["2"] * 3 + ["1"] * 3 + ["1"] * 3 + ["0.5"] * 3
    >>> _ = open("sgd.csv", "w").write("material," + ",".join(SGD_COLUMNS) + chr(10) + "shiny," + ",".join(row) + chr(10))
    >>> list(read_sgd("sgd.csv"))
    ['shiny']
    """
    out = {}
    for material, r in _read_table(csv_path, SGD_COLUMNS, "SGD").items():
        params = {f: tuple(r[f"{f}_{c}"] for c in "rgb") for f in _SGD_FIELDS}
        params["lam"] = params.pop("lambda")
        out[material] = SGD(**params)
    return out
