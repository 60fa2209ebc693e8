"""Shared pieces of the measured-BRDF readers: file bytes, errors, cosine sampling.

Measured data are tables, not lobes: every reader's BRDF is importance-sampled by the
cosine-weighted hemisphere (Malley's method), so ``pdf(wi, wo) = max(0, cos theta_i) / pi``
and ``weight = eval_cos / pdf = pi f_r``. Directions follow the package convention:
``wi`` is the light, ``wo`` the view, ``(..., 3)`` float64 in the local frame.

``eval``, ``eval_cos`` and ``sample`` run one compiled parallel loop (:mod:`._kernels`,
Numba, compiled on first use; batches below ``microfacet.kernels.PARALLEL_MIN`` on one
thread) when Numba is available (:data:`microfacet.kernels.AVAILABLE`); the NumPy code of
each reader is the reference they are tested against.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .. import backend, kernels
from ..brdf import BRDF
from ..protocol import directions as as_dirs   # the one direction check of every BRDF
from ..protocol import into, into_sample, output, sample_outputs, uniforms
from ..errors import MicrofacetError
from ..geometry import cosine_hemisphere_pdf, square_to_cosine_hemisphere

__all__ = ["MeasuredBRDF", "file_error", "check_finite", "as_dirs", "compiled_kernels"]


def compiled_kernels():
    """The module of compiled loops (:mod:`._kernels`, imports Numba on first use), or
    ``None`` without Numba, with ``MICROFACET_NUMBA=0`` or while
    ``microfacet.kernels.AVAILABLE`` is False (:func:`microfacet.backend.choose`): then every reader
    runs its NumPy reference.

    Returns
    -------
    module or None
        :mod:`microfacet.measured._kernels`, or None.

    Examples
    --------
    >>> from microfacet import backend
    >>> (compiled_kernels() is None) == (backend.choose() == backend.NUMPY)
    True
    """
    if backend.choose() != backend.NUMBA:
        return None
    from . import _kernels
    return _kernels


def _rows(a, k: int) -> np.ndarray:
    """``a`` as a read-only C-contiguous ``(N, k)`` float64 array (a copy only if needed). Read-only
    whether or not a copy was made: Numba compiles a loop once per read-only flag of its arguments,
    and a broadcast view is read-only while a copy is not (two versions of each loop, each compiled
    at first use, instead of the one that ``python -m microfacet.kernels_extra --precompile`` makes)."""
    rows = np.ascontiguousarray(np.reshape(a, (-1, k)), dtype=np.float64)
    if rows.flags.writeable:
        rows = rows.view()
        rows.flags.writeable = False
    return rows


def file_error(path, what: str) -> MicrofacetError:
    """A :class:`MicrofacetError` naming the file and what is wrong with it.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    what : str
        What is wrong.

    Returns
    -------
    MicrofacetError
        The error (not raised).

    Examples
    --------
    >>> file_error("data/gold.binary", "truncated")
    MicrofacetError('data/gold.binary: truncated')
    """
    return MicrofacetError(f"{os.fspath(path)}: {what}")


def check_finite(path, values: np.ndarray, what: str) -> None:
    """Raise if ``values`` hold NaN or infinity, counting them in the message.

    Parameters
    ----------
    path : str or os.PathLike
        The file, for the message.
    values : ndarray
        The values read.
    what : str
        What they are, for the message.

    Examples
    --------
    >>> import numpy as np
    >>> check_finite("a.bin", np.ones(3), "values")           # passes: returns None
    >>> check_finite("a.bin", np.array([1.0, np.nan, np.inf]), "values")
    Traceback (most recent call last):
        ...
    microfacet.errors.MicrofacetError: a.bin: values holds 2 NaN or infinite value(s)
    """
    bad = ~np.isfinite(values)
    if bad.any():
        raise file_error(path, f"{what} holds {int(bad.sum())} NaN or infinite value(s)")


class MeasuredBRDF(BRDF):
    """Base of the tabulated readers: the BRDF protocol with cosine-hemisphere sampling.

    Subclasses implement the NumPy reference of ``f_r`` (``_eval_numpy``) or of ``f_r cos
    theta_i`` (``_eval_cos_numpy``), the other one following by the factor ``cos theta_i``
    (0 below either horizon), and ``_kernel``, the compiled loops of the same.

    Attributes
    ----------
    path : pathlib.Path
        The file the data were read from.
    format : str
        ``"merl"``, ``"rgl"`` or ``"utia"``.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.measured import UTIABRDF
    >>> brdf = UTIABRDF(np.full((6, 48, 6, 48, 3), 0.2))      # a constant table
    >>> isinstance(brdf, MeasuredBRDF), brdf.format
    (True, 'utia')
    >>> wo = np.array([0.0, 0.6, 0.8])
    >>> brdf.eval(np.array([0.6, 0.0, 0.8]), wo)
    array([0.2, 0.2, 0.2])
    >>> wi, weight, pdf = brdf.sample(np.array([0.5, 0.5]), wo)     # cosine-hemisphere sampling
    >>> round(float(pdf), 4) == round(float(wi[2] / np.pi), 4)
    True
    """

    format = ""

    def __init__(self, path):
        self.path = Path(path)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({os.fspath(self.path)!r})"

    def _kernel(self):
        """``(eval loop, sample loop, tables)`` of the compiled path (``tables``: the reader's record,
        passed whole to the loops), or ``None``: then
        :meth:`eval`, :meth:`eval_cos` and :meth:`sample` run the NumPy reference."""
        return None

    def _eval_numpy(self, wi, wo) -> np.ndarray:
        """NumPy reference of ``f_r`` (unit, broadcastable ``wi``, ``wo``): ``f_r cos theta_i /
        cos theta_i``, 0 below the horizon."""
        fc, zi = self._eval_cos_numpy(wi, wo), wi[..., 2:3]
        return np.divide(fc, zi, out=np.zeros(np.broadcast_shapes(fc.shape, zi.shape)), where=zi > 0)

    def _eval_cos_numpy(self, wi, wo) -> np.ndarray:
        """NumPy reference of ``f_r cos theta_i``: ``f_r max(cos theta_i, 0)``."""
        return self._eval_numpy(wi, wo) * np.maximum(wi[..., 2:3], 0.0)

    def _eval(self, wi, wo, cosine: bool, out=None) -> np.ndarray:
        wi, wo = as_dirs(wi, "wi"), as_dirs(wo, "wo")
        k = self._kernel()
        if k is None:
            return into(out, self._eval_cos_numpy(wi, wo) if cosine else self._eval_numpy(wi, wo), (wi, wo))
        shape = np.broadcast_shapes(wi.shape, wo.shape)
        out = output(out, shape, np.float64, "out", (wi, wo))
        kernels.launch(k[0], out.size // 3, _rows(np.broadcast_to(wi, shape), 3),
                        _rows(np.broadcast_to(wo, shape), 3), cosine, out.reshape(-1, 3), k[2])
        return out

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
        return self._eval(wi, wo, False, out)

    def eval_cos(self, wi, wo, out=None) -> np.ndarray:
        """``f_r(wi, wo) cos theta_i``, RGB ``(..., 3)`` (thesis: ``evalp``).

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
        return self._eval(wi, wo, True, out)

    def pdf(self, wi, wo, out=None) -> np.ndarray:
        """Density of :meth:`sample`: ``cos theta_i / pi`` (0 if ``wo`` is below the horizon).

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
        wi, wo = as_dirs(wi, "wi"), as_dirs(wo, "wo")
        return into(out, np.where(wo[..., 2] > 0, cosine_hemisphere_pdf(wi), 0.0), (wi, wo))

    def sample(self, u, wo, out=None):
        """Cosine-weighted light directions: ``(wi, eval_cos / pdf, pdf)``; weight and pdf
        are 0 where ``wo`` or ``wi`` is below the horizon.

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
        wo = as_dirs(wo, "wo")
        u = uniforms(u)
        shape = np.broadcast_shapes(u.shape[:-1], wo.shape[:-1])
        k = self._kernel()
        if k is not None:
            wi, weight, pdf = sample_outputs(out, shape, np.float64, (u, wo))
            kernels.launch(k[1], pdf.size, _rows(np.broadcast_to(u, shape + (2,)), 2),
                            _rows(np.broadcast_to(wo, shape + (3,)), 3), wi.reshape(-1, 3), weight.reshape(-1, 3),
                            pdf.reshape(-1), k[2])
            return wi, weight, pdf
        wi = square_to_cosine_hemisphere(np.broadcast_to(u, shape + (2,)))
        wo = np.broadcast_to(wo, shape + (3,))
        pdf = self.pdf(wi, wo)
        ok = pdf > 0
        fc = self.eval_cos(wi, wo)
        weight = np.divide(fc, pdf[..., None], out=np.zeros_like(fc), where=ok[..., None])
        return into_sample(out, (wi, weight, pdf), (u, wo))
