"""Shared pieces of the measured-BRDF readers: file bytes, errors, cosine sampling.

Measured data are tables, not lobes: every reader's BRDF is importance-sampled by the
cosine-weighted hemisphere (Malley's method), so ``pdf(wi, wo) = max(0, cos theta_i) / pi``
and ``weight = eval_cos / pdf = pi f_r``. Directions follow the package convention:
``wi`` is the light, ``wo`` the view, ``(..., 3)`` float64 in the local frame.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..brdf import BRDF, _uniforms
from ..brdf import _dirs as as_dirs   # the one direction check of every BRDF
from ..errors import MicrofacetError
from ..geometry import cosine_hemisphere_pdf, square_to_cosine_hemisphere

__all__ = ["MeasuredBRDF", "read_bytes", "file_error", "check_finite", "as_dirs"]


def file_error(path, what: str) -> MicrofacetError:
    """A :class:`MicrofacetError` naming the file and what is wrong with it."""
    return MicrofacetError(f"{os.fspath(path)}: {what}")


def read_bytes(path) -> bytes:
    """All bytes of ``path`` (opened read-only); an unreadable file is a ``MicrofacetError``."""
    try:
        return Path(path).read_bytes()
    except OSError as e:
        raise file_error(path, f"cannot read file ({e.strerror or e})") from e


def check_finite(path, values: np.ndarray, what: str) -> None:
    """Raise if ``values`` hold NaN or infinity, counting them in the message."""
    bad = ~np.isfinite(values)
    if bad.any():
        raise file_error(path, f"{what} holds {int(bad.sum())} NaN or infinite value(s)")


class MeasuredBRDF(BRDF):
    """Base of the tabulated readers: the BRDF protocol with cosine-hemisphere sampling.

    Subclasses implement :meth:`eval` (``f_r``, RGB) or :meth:`eval_cos`; the other one
    follows by the factor ``cos theta_i`` (0 below either horizon).

    Attributes
    ----------
    path : pathlib.Path
        The file the data were read from.
    format : str
        ``"merl"``, ``"rgl"`` or ``"utia"``.
    """

    format = ""

    def __init__(self, path):
        self.path = Path(path)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({os.fspath(self.path)!r})"

    def eval_cos(self, wi, wo) -> np.ndarray:
        """``f_r(wi, wo) cos theta_i``, RGB ``(..., 3)`` (thesis: ``evalp``)."""
        wi = as_dirs(wi, "wi")
        return self.eval(wi, wo) * np.maximum(wi[..., 2:3], 0.0)

    def pdf(self, wi, wo) -> np.ndarray:
        """Density of :meth:`sample`: ``cos theta_i / pi`` (0 if ``wo`` is below the horizon)."""
        wi, wo = as_dirs(wi, "wi"), as_dirs(wo, "wo")
        return np.where(wo[..., 2] > 0, cosine_hemisphere_pdf(wi), 0.0)

    def sample(self, u, wo):
        """Cosine-weighted light directions: ``(wi, eval_cos / pdf, pdf)``; weight and pdf
        are 0 where ``wo`` or ``wi`` is below the horizon."""
        wo = as_dirs(wo, "wo")
        u = _uniforms(u)
        shape = np.broadcast_shapes(u.shape[:-1], wo.shape[:-1])
        wi = square_to_cosine_hemisphere(np.broadcast_to(u, shape + (2,)))
        wo = np.broadcast_to(wo, shape + (3,))
        pdf = self.pdf(wi, wo)
        ok = pdf > 0
        fc = self.eval_cos(wi, wo)
        weight = np.divide(fc, pdf[..., None], out=np.zeros_like(fc), where=ok[..., None])
        return wi, weight, pdf
