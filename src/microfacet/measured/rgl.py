"""RGL material database BRDFs (Dupuy & Jakob 2018, "An Adaptive Parameterization for
Efficient Material Acquisition and Rendering", ACM TOG 37(6)): ``.bsdf`` tensor files.

The measured BRDF is stored in a parameterization warped by the material's own visible
NDF: for a view direction ``v`` (parameters ``(phi_v, theta_v)``), a half vector ``m``
(unit coordinates ``u_m = (sqrt(2 theta_m / pi), (phi_m [- phi_v] + pi) / (2 pi))``) maps
to the uniforms ``s = VNDF^-1(u_m | v)`` of the ``vndf`` table's sample warp, and the
value is read from the ``rgb`` table at ``s``:

    f_r(l, v) cos theta_l = rgb(s | phi_v, theta_v) D(u_m) / (4 sigma(u_v))

where ``D`` is the ``ndf`` table and ``sigma`` the projected-area table (the last factor
only if the file's ``jacobian`` flag is set). All tables are ``Marginal2D`` bilinear
interpolants (:mod:`.marginal2d`). Evaluation is the same as Mitsuba 3's ``measured``
plugin (``eval``) and rgl-epfl/brdf-loader (``powitacq_rgb``), with their conventions:

* the view ``v`` is Mitsuba's ``si.wi`` (the tables' parameter), the light ``l`` its ``wo``;
* interpolated RGB can be slightly negative where the spectral data lie outside the sRGB
  gamut: Mitsuba keeps such values, as we do by default (``clip_negative=True`` clips
  them to 0 like ``powitacq_rgb``);
* files whose ``phi_i`` span ``2 pi / r`` (``r = 2`` or ``4``) are mirrored into the
  stored half or quadrant by the signs of ``v``;
* the ``luminance`` table only serves Mitsuba's importance sampling and the ``valid``
  bit mask is not used, as in Mitsuba; sampling here is cosine-weighted.
"""
from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from .base import MeasuredBRDF, as_dirs, check_finite, compiled_kernels, file_error
from .marginal2d import Marginal2D
from .tensor_file import read_tensor_file

__all__ = ["RGLBRDF", "RGLTables", "read_rgl"]


class RGLTables(NamedTuple):
    """The tables and flags of an :class:`RGLBRDF` as its compiled loops read them
    (:mod:`microfacet.measured._kernels`, passed whole): the parameter nodes ``phi_nodes``,
    ``theta_nodes`` of the view, the VNDF's ``vc`` ``(value, conditional CDF)`` pairs, row
    integrals ``rows`` and marginal CDF ``marg`` (``normalized``: whether it sums to 1), the
    ``rgb`` table, the NDF ``ndf`` and projected area ``sigma`` tables (Dupuy & Jakob 2018), and
    the flags ``isotropic``, ``reduction`` (the file's azimuthal symmetry), ``jacobian`` and
    ``clip_negative`` of :class:`RGLBRDF`. Example: ``brdf._kernel()[2].isotropic``.

    Attributes
    ----------
    phi_nodes, theta_nodes : ndarray
        Parameter nodes of the view.
    vc : ndarray
        VNDF values and conditional CDFs.
    rows, marg : ndarray
        Row integrals and marginal CDF.
    normalized : bool
        Whether the marginal sums to 1.
    rgb, ndf, sigma : ndarray
        The RGB, NDF and projected-area tables.
    isotropic : bool
        Isotropic file.
    reduction : int
        Azimuthal symmetry of the file.
    jacobian : bool
        The file's ``jacobian`` flag (the ``sigma`` factor applies).
    clip_negative : bool
        As :class:`RGLBRDF`.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.kernels_extra import synthetic_rgl
    >>> brdf = RGLBRDF(synthetic_rgl(np.random.default_rng(0)))
    >>> k = brdf._kernel()          # None without Numba (the NumPy reference runs)
    >>> k is None or (isinstance(k[2], RGLTables) and k[2].isotropic)
    True
    """

    phi_nodes: np.ndarray
    theta_nodes: np.ndarray
    vc: np.ndarray
    rows: np.ndarray
    marg: np.ndarray
    normalized: bool
    rgb: np.ndarray
    ndf: np.ndarray
    sigma: np.ndarray
    isotropic: bool
    reduction: int
    jacobian: bool
    clip_negative: bool

FLOAT_FIELDS = ("theta_i", "phi_i", "ndf", "sigma", "vndf", "luminance", "rgb")


def theta2u(theta):
    """Unit coordinate of an elevation: ``sqrt(2 theta / pi)``."""
    return np.sqrt(np.maximum(theta, 0.0) * (2.0 / np.pi))


def phi2u(phi):
    """Unit coordinate of an azimuth: ``(phi + pi) / (2 pi)``."""
    return (phi + np.pi) / (2.0 * np.pi)


def elevation(w):
    """``theta`` of unit ``w``, stable near the pole: ``2 asin(|w - z| / 2)``."""
    dist = np.sqrt(w[..., 0] ** 2 + w[..., 1] ** 2 + (w[..., 2] - 1.0) ** 2)
    return 2.0 * np.arcsin(np.minimum(0.5 * dist, 1.0))


def _require(path, f: dict, name: str, dtype: str, ndim: int) -> np.ndarray:
    if name not in f:
        hint = " (spectral file: use the _rgb variant)" if name == "rgb" and "spectra" in f else ""
        raise file_error(path, f"RGL .bsdf file lacks the field {name!r}{hint}")
    a = f[name]
    if a.dtype != np.dtype(dtype) or a.ndim != ndim:
        raise file_error(path, f"RGL field {name!r} is {a.dtype} with shape {a.shape}, "
                               f"expected {ndim}-D {np.dtype(dtype)}")
    return a


def read_rgl(data: bytes, path) -> dict[str, np.ndarray]:
    """The fields of an RGL ``_rgb`` ``.bsdf`` file, checked as Mitsuba 3 does
    (dtypes, ranks, consistent ``phi_i`` / ``theta_i`` / table shapes) plus finiteness.

    Parameters
    ----------
    data : bytes
        Uncompressed file content.
    path : str or os.PathLike
        The file, for messages.

    Returns
    -------
    dict of str to ndarray
        The fields.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.kernels_extra import synthetic_rgl
    >>> from microfacet.measured import write_tensor_file
    >>> fields = read_rgl(write_tensor_file(synthetic_rgl(np.random.default_rng(0))), "synthetic.bsdf")
    >>> fields["rgb"].shape, fields["theta_i"].dtype
    ((1, 4, 3, 8, 8), dtype('float32'))
    >>> del fields["ndf"]
    >>> read_rgl(write_tensor_file(fields), "bad.bsdf")
    Traceback (most recent call last):
        ...
    microfacet.errors.MicrofacetError: bad.bsdf: RGL .bsdf file lacks the field 'ndf'
    """
    f = read_tensor_file(data, path)
    for name, dtype, ndim in (("description", "u1", 1), ("jacobian", "u1", 1),
                              ("theta_i", "<f4", 1), ("phi_i", "<f4", 1), ("ndf", "<f4", 2),
                              ("sigma", "<f4", 2), ("vndf", "<f4", 4), ("luminance", "<f4", 4),
                              ("rgb", "<f4", 5)):
        _require(path, f, name, dtype, ndim)
    n_phi, n_theta = len(f["phi_i"]), len(f["theta_i"])
    lum, rgb = f["luminance"].shape, f["rgb"].shape
    if (f["vndf"].shape[:2] != (n_phi, n_theta) or lum[:2] != (n_phi, n_theta)
            or rgb[:3] != (n_phi, n_theta, 3) or rgb[3:] != lum[2:] or lum[2] != lum[3]
            or f["jacobian"].shape != (1,)):
        raise file_error(path, f"RGL tables disagree: phi_i {n_phi}, theta_i {n_theta}, vndf "
                               f"{f['vndf'].shape}, luminance {lum}, rgb {rgb}, jacobian {f['jacobian'].shape}")
    if min(f["ndf"].shape + f["sigma"].shape + f["vndf"].shape[2:] + rgb[3:]) < 2:
        raise file_error(path, "RGL tables need at least 2 samples along each axis")
    for name in ("theta_i", "phi_i"):
        if np.any(np.diff(f[name]) <= 0):
            raise file_error(path, f"RGL field {name!r} is not increasing")
    for name in FLOAT_FIELDS:
        check_finite(path, f[name], f"RGL field {name!r}")
    return f


class RGLBRDF(MeasuredBRDF):
    """An RGL ``_rgb`` ``.bsdf`` BRDF, evaluated like Mitsuba 3's ``measured`` plugin.

    Parameters
    ----------
    fields : dict of ndarray
        The file's fields (:func:`read_rgl`).
    path : str or os.PathLike
        The file, for messages and ``repr``.
    clip_negative : bool
        Clip negative (out-of-gamut) RGB values to 0 (default False: as Mitsuba 3).

    Attributes
    ----------
    fields : dict of ndarray
        The file's raw fields (``theta_i``, ``phi_i``, ``ndf``, ``sigma``, ``vndf``,
        ``luminance``, ``rgb``, ``valid``, ...).
    ndf_table : ndarray, (n_phi, n_theta)
        The file's own NDF ``D``: row ``r``, column ``c`` at ``phi_m = (2 r / (n_phi - 1)
        - 1) pi``, ``theta_m = (c / (n_theta - 1))^2 pi / 2`` (retrieved by the authors from
        retro-reflection by power iterations); :meth:`ndf` interpolates it.
    description : str
    isotropic : bool
    clip_negative : bool
        Clip negative (out-of-gamut) RGB values to 0 (default False: as Mitsuba 3).

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.kernels_extra import synthetic_rgl
    >>> brdf = RGLBRDF(synthetic_rgl(np.random.default_rng(0)), "synthetic.bsdf")
    >>> brdf.isotropic, brdf.description
    (True, 'synthetic material')
    >>> n = np.array([0.0, 0.0, 1.0])
    >>> brdf.eval(n, n).round(3), round(float(brdf.ndf(n)), 3)
    (array([0.718, 0.845, 0.802]), 3.0)
    """

    format = "rgl"

    def __init__(self, fields: dict, path="", clip_negative: bool = False):
        super().__init__(path)
        self.clip_negative = bool(clip_negative)
        self.fields = fields
        self.description = bytes(fields["description"]).decode("utf-8", "replace")
        self.ndf_table = fields["ndf"]
        self.sigma_table = fields["sigma"]
        phi_i, theta_i = fields["phi_i"], fields["theta_i"]
        self.isotropic = len(phi_i) <= 2
        self.reduction = 0 if self.isotropic else int(np.rint(2 * np.pi / (phi_i[-1] - phi_i[0])))
        self.jacobian = bool(fields["jacobian"][0])
        params = (phi_i, theta_i)
        self._ndf = Marginal2D(fields["ndf"])
        self._sigma = Marginal2D(fields["sigma"])
        self._vndf = Marginal2D(fields["vndf"], params, normalize=True, invertible=True)
        self._rgb = Marginal2D(np.moveaxis(fields["rgb"], 2, -1), params)   # channels last

    def ndf(self, h) -> np.ndarray:
        """The file's NDF ``D(h)`` (bilinear in ``(sqrt(2 theta_h / pi), (phi_h + pi) / 2 pi)``).

        Parameters
        ----------
        h : (..., 3) array_like
            Unit microfacet normals.

        Returns
        -------
        (...) ndarray
            ``D(h)`` (0 below the horizon).
        """
        h = as_dirs(h, "h")
        d = self._ndf.eval(theta2u(elevation(h)), phi2u(np.arctan2(h[..., 1], h[..., 0])))
        return np.where(h[..., 2] > 0, d, 0.0)

    def sigma(self, w) -> np.ndarray:
        """The file's projected microsurface area ``sigma(w)`` (same parameterization).

        Parameters
        ----------
        w : (..., 3) array_like
            Unit directions.

        Returns
        -------
        (...) ndarray
            ``sigma(w)``.
        """
        w = as_dirs(w, "w")
        return self._sigma.eval(theta2u(elevation(w)), phi2u(np.arctan2(w[..., 1], w[..., 0])))

    def _mirror(self, wi, wo):
        """Fold both directions into the stored azimuth range (``reduction`` 2 or 4) by
        the signs of the view ``wo``, as Mitsuba's ``mulsign_neg``."""
        if self.reduction < 2:
            return wi, wo
        sy = wo[..., 1]
        sx = wo[..., 0] if self.reduction == 4 else sy
        flip = np.stack([np.where(np.signbit(sx), 1.0, -1.0), np.where(np.signbit(sy), 1.0, -1.0),
                         np.ones_like(sx)], axis=-1)
        return wi * flip, wo * flip

    @functools.cached_property
    def _tables(self) -> tuple:
        """The arrays of the compiled loop (:func:`._kernels._invert`): parameter nodes,
        VNDF ``(value, conditional CDF)`` pairs, row integrals, marginal CDF, RGB, NDF, sigma."""
        v = self._vndf
        vc = np.stack([v.data[..., 0], v.cond], axis=-1)
        return (v.params[0], v.params[1], vc, np.ascontiguousarray(v.cond[..., -1]), v.marg, v.normalized,
                np.ascontiguousarray(self._rgb.data), self._ndf.data[0, :, :, 0].copy(), self._sigma.data[0, :, :, 0].copy())

    def _kernel(self):
        k = compiled_kernels()
        if k is None:
            return None
        return k.eval_rgl, k.sample_rgl, RGLTables(*self._tables, self.isotropic, self.reduction, self.jacobian,
                                                   self.clip_negative)

    def _eval_cos_numpy(self, wi, wo) -> np.ndarray:
        """``f_r(wi, wo) cos theta_i``, RGB ``(..., 3)`` (Mitsuba's ``eval`` with
        ``si.wi = wo``); 0 below either horizon."""
        wi, wo = np.broadcast_arrays(wi, wo)
        up = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        with np.errstate(divide="ignore", invalid="ignore"):     # masked by `up` below
            wi, wo = self._mirror(wi, wo)
            m = wi + wo
            m = m / np.linalg.norm(m, axis=-1, keepdims=True).clip(1e-300)
            theta_v, phi_v = elevation(wo), np.arctan2(wo[..., 1], wo[..., 0])
            theta_m, phi_m = elevation(m), np.arctan2(m[..., 1], m[..., 0])
            um_x = theta2u(theta_m)
            um_y = phi2u(phi_m - phi_v if self.isotropic else phi_m)
            um_y = um_y - np.floor(um_y)
            s1, s2, _ = self._vndf.invert(um_x, um_y, (phi_v, theta_v))
            rgb = self._rgb.eval(s1, s2, (phi_v, theta_v))
            if self.clip_negative:
                rgb = np.maximum(rgb, 0.0)                   # out-of-gamut RGB
            if self.jacobian:
                scale = self._ndf.eval(um_x, um_y) / (4.0 * self._sigma.eval(theta2u(theta_v), phi2u(phi_v)))
                rgb = rgb * scale[..., None]
        return np.where(up[..., None], rgb, 0.0)
