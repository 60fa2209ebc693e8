"""A diffuse body seen through its smooth surface: the Lambertian term of a dielectric.

Light that enters a dielectric (paint, plastic, rubber, wood finish) crosses its surface
twice, and the surface's Fresnel reflectance takes a share of it each time, a share that
grows toward grazing angles. The diffuse term of such a material is therefore darker at
grazing angles than a Lambertian one, where its specular reflection is brighter: its
directional albedo stays flat while that of "Lambertian + specular" rises. This module's
:class:`TransmittedLambertian` is

    f(wi, wo) = R / pi * t(cos th_i) t(cos th_o) / t(1)^2,    t(mu) = 1 - F(eta, mu),

``F`` the unpolarized Fresnel reflectance of a smooth interface of relative index ``eta``
(:class:`microfacet.fresnel.Dielectric`). It is the diffuse coupling of Kelemen &
Szirmay-Kalos 2001 with a smooth coat (whose coat albedo is ``F`` itself) and of Ashikhmin &
Shirley 2000's diffuse term, which uses Schlick's form of ``F`` and a fixed index; the
normalization by ``t(1)^2`` makes ``R`` the reflectance at normal incidence, so its albedo
never exceeds ``R`` (``<= 0.95 R`` for ``eta = 1.5``, tested). Sampled by the cosine warp.

Example
-------
>>> import numpy as np
>>> base = TransmittedLambertian([0.8, 0.4, 0.1])
>>> n = np.array([0.0, 0.0, 1.0])
>>> bool(np.allclose(base.eval(n, n), np.array([0.8, 0.4, 0.1]) / np.pi))
True
"""
from __future__ import annotations

import numpy as np

from .brdf import BRDF, Lambertian, unit_directions
from .fresnel import Dielectric

__all__ = ["TransmittedLambertian"]


class TransmittedLambertian(BRDF):
    """``R / pi * t(cos th_i) t(cos th_o) / t(1)^2`` with ``t = 1 - F_dielectric(eta)``
    (module docstring; Kelemen & Szirmay-Kalos 2001, Ashikhmin & Shirley 2000).

    Parameters
    ----------
    reflectance : float or (3,)
        ``R``, the reflectance at normal incidence, in ``[0, 1]`` per channel.
    eta : float
        Relative index of the surface the light crosses, ``> 1`` (default 1.5: paints,
        plastics).

    Examples
    --------
    >>> import numpy as np
    >>> body = TransmittedLambertian(reflectance=(0.5, 0.2, 0.1), eta=1.5)
    >>> wi = wo = np.array([0.0, 0.0, 1.0])
    >>> (body.eval_cos(wi, wo) * np.pi).round(4)       # R at normal incidence
    array([0.5, 0.2, 0.1])
    >>> grazing = np.array([np.sin(1.4), 0.0, np.cos(1.4)])
    >>> (body.eval_cos(grazing, wo) / np.cos(1.4) * np.pi).round(4)   # darker: the surface reflects more there
    array([0.315, 0.126, 0.063])
    """

    def __init__(self, reflectance=1.0, eta: float = 1.5):
        self._lambertian = Lambertian(reflectance)        # checks R
        if not (np.isfinite(eta) and eta > 1.0):
            raise ValueError(f"eta must be a finite number > 1, got {eta!r}")
        self.eta = float(eta)
        self._fresnel = Dielectric(self.eta)
        self._t1 = float(self.transmittance(np.ones(1))[0])

    @property
    def reflectance(self) -> np.ndarray:
        return self._lambertian.reflectance

    def __repr__(self) -> str:
        return f"TransmittedLambertian(reflectance={self.reflectance.tolist()}, eta={self.eta!r})"

    def transmittance(self, mu) -> np.ndarray:
        """``t(mu) = 1 - F(eta, mu)``, 0 below the horizon.

        Parameters
        ----------
        mu : array_like
            Cosines.

        Returns
        -------
        ndarray
            ``1 - F``, 0 where ``mu <= 0``.
        """
        mu = np.asarray(mu, dtype=np.float64)
        f = self._fresnel(np.clip(mu, 0.0, 1.0))[..., 0]
        return np.where(mu > 0, 1.0 - f, 0.0)

    def _factor(self, wi, wo) -> np.ndarray:
        return (self.transmittance(wi[..., 2]) * self.transmittance(wo[..., 2]) / (self._t1 * self._t1))[..., None]

    @staticmethod
    def _into(out, value):
        if out is None:
            return value
        out[...] = value
        return out

    def eval_cos(self, wi, wo, out=None) -> np.ndarray:
        wi, wo = unit_directions(wi, "wi"), unit_directions(wo, "wo")
        return self._into(out, self._lambertian.eval_cos(wi, wo) * self._factor(wi, wo))

    def pdf(self, wi, wo, out=None) -> np.ndarray:
        return self._lambertian.pdf(wi, wo, out=out)

    def sample(self, u, wo, out=None):
        wo = unit_directions(wo, "wo")
        wi, weight, pdf = self._lambertian.sample(u, wo)
        weight = weight * self._factor(wi, np.broadcast_to(wo, wi.shape))
        if out is None:
            return wi, weight, pdf
        for o, v in zip(out, (wi, weight, pdf)):
            o[...] = v
        return out
