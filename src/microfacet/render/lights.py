"""Light sources of the shading harness: a directional light and a lat-long environment.

Environment maps are ``(H, W, 3)`` linear RGB radiance in the world frame of
:mod:`~microfacet.render.sphere` (y up, z toward the viewer). Row ``i`` spans polar angle
``theta = arccos(w_y)`` in ``[i, i+1] pi / H`` (row 0 at the zenith), column ``j`` spans
azimuth ``phi = atan2(w_x, w_z)`` in ``-pi + [j, j+1] 2 pi / W``, so the image centre is
the direction toward the viewer (what a mirror sphere shows at its centre) and the
image's left/right edges are the direction behind the sphere.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..errors import MicrofacetError
from ..geometry import dot, normalize
from ..io import read_exr

__all__ = ["DirectionalLight", "Environment", "procedural_sky", "latlong_directions"]


@dataclass(frozen=True)
class DirectionalLight:
    """A distant light from world direction ``direction`` (toward the light) delivering
    ``irradiance`` ``E`` (scalar or RGB) on a surface facing it: reflected radiance is
    ``L_o = E f_r(wi, wo) cos theta_i`` (rendering equation with a Dirac emitter).

    Parameters
    ----------
    direction : (float, float, float)
        World direction toward the light (normalized by the renderer).
    irradiance : float or (float, float, float)
        ``E``, scalar or RGB.

    Examples
    --------
    >>> light = DirectionalLight(direction=(0.0, 0.0, 2.0), irradiance=(1.0, 0.5, 0.25))
    >>> light.w, light.rgb                                  # unit direction, RGB irradiance
    (array([0., 0., 1.]), array([1.  , 0.5 , 0.25]))
    """

    direction: tuple[float, float, float] = (-0.5, 0.5, 1.0)
    irradiance: float | tuple[float, float, float] = 1.0

    def __post_init__(self):
        d = np.asarray(self.direction, dtype=np.float64)
        if d.shape != (3,) or not np.all(np.isfinite(d)) or not np.any(d):
            raise ValueError(f"direction must be three finite numbers, not all 0, got {self.direction!r}")
        e = np.asarray(self.irradiance, dtype=np.float64)
        if e.shape not in ((), (3,)) or not np.all(np.isfinite(e)) or np.any(e < 0):
            raise ValueError(f"irradiance must be a finite value >= 0 or three (RGB), got {self.irradiance!r}")

    @property
    def w(self) -> np.ndarray:
        """Unit world direction toward the light."""
        return normalize(np.asarray(self.direction, dtype=np.float64))

    @property
    def rgb(self) -> np.ndarray:
        """Irradiance as an RGB ``(3,)`` array."""
        return np.broadcast_to(np.asarray(self.irradiance, dtype=np.float64), (3,))


def latlong_directions(height: int, width: int) -> np.ndarray:
    """World directions ``(height, width, 3)`` of the texel centres of a lat-long map.

    Parameters
    ----------
    height, width : int
        Map size, texels.

    Returns
    -------
    (height, width, 3) ndarray
        Unit world directions (y up).

    Examples
    --------
    >>> import numpy as np
    >>> w = latlong_directions(4, 8)
    >>> w.shape, bool(np.allclose(np.linalg.norm(w, axis=-1), 1))
    ((4, 8, 3), True)
    """
    theta = (np.arange(height) + 0.5) / height * np.pi
    phi = (np.arange(width) + 0.5) / width * 2.0 * np.pi - np.pi
    st = np.sin(theta)[:, None]
    return np.stack(np.broadcast_arrays(st * np.sin(phi), np.cos(theta)[:, None], st * np.cos(phi)), -1)


class Environment:
    """Distant lighting from a lat-long radiance map, looked up bilinearly.

    Parameters
    ----------
    radiance : array_like, (H, W, 3)
        Linear RGB radiance, finite and ``>= 0`` (layout in the module docstring).

    Examples
    --------
    >>> import numpy as np
    >>> sky = Environment(procedural_sky(32, 64))
    >>> sky.radiance(np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])).round(3)   # zenith (y up) and nadir
    array([[0.18 , 0.32 , 0.65 ],
           [0.05 , 0.045, 0.04 ]])
    """

    def __init__(self, radiance):
        r = np.asarray(radiance, dtype=np.float64)
        if r.ndim != 3 or r.shape[2] != 3 or r.shape[0] < 1 or r.shape[1] < 1:
            raise ValueError(f"environment radiance must be (H, W, 3), got shape {r.shape}")
        if not np.all(np.isfinite(r)) or np.any(r < 0):
            raise ValueError("environment radiance must be finite and >= 0")
        self.map = r
        # one wrapped column on each side and a repeated last row: the four bilinear
        # neighbours of any lookup are then base, base + 1, base + W + 2, base + W + 3
        wrapped = np.concatenate([r[:, -1:], r, r[:, :1]], axis=1)
        self._texels = np.concatenate([wrapped, wrapped[-1:]], axis=0).reshape(-1, 3)

    @classmethod
    def from_exr(cls, path: str | os.PathLike) -> Environment:
        """Load a lat-long EXR (RGB, RGBA or Y) as an environment.

        Parameters
        ----------
        path : str or os.PathLike
            The EXR file.

        Returns
        -------
        Environment
            The environment.
        """
        image = read_exr(path)
        rgb = np.repeat(image, 3, axis=2) if image.shape[2] == 1 else image[..., :3]
        if np.any(rgb < 0):
            raise MicrofacetError(f"{path}: environment radiance has negative values")
        return cls(rgb)

    def radiance(self, w) -> np.ndarray:
        """Radiance ``L_env(w)`` ``(..., 3)`` arriving from world directions ``w``.

        Bilinear between texel centres, wrapping in ``phi`` and clamped in ``theta``.

        Parameters
        ----------
        w : (..., 3) array_like
            Unit world directions (y up).

        Returns
        -------
        (..., 3) ndarray
            Radiance.
        """
        w = np.asarray(w, dtype=np.float64)
        h, wd = self.map.shape[:2]
        theta = np.arccos(np.clip(w[..., 1], -1.0, 1.0))
        phi = np.arctan2(w[..., 0], w[..., 2])
        fy = np.clip(theta * (h / np.pi) - 0.5, 0.0, h - 1.0)
        fx = np.clip((phi * (0.5 / np.pi) + 0.5) * wd - 0.5, -1.0, wd - 1e-9)
        y0, x0 = np.floor(fy), np.floor(fx)
        ty, tx = (fy - y0)[..., None], (fx - x0)[..., None]
        base = y0.astype(np.intp) * (wd + 2) + x0.astype(np.intp) + 1
        t = self._texels
        top = t[base] + tx * (t[base + 1] - t[base])
        bottom = t[base + wd + 2] + tx * (t[base + wd + 3] - t[base + wd + 2])
        return top + ty * (bottom - top)


def _smoothstep(e0, e1, x):
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _disk_light(w, centre, radius_deg, radiance, soft=0.25):
    """Round light of angular radius ``radius_deg`` with a soft edge, ``(..., 3)``."""
    c = normalize(np.asarray(centre, dtype=np.float64))
    angle = np.degrees(np.arccos(np.clip(dot(w, c), -1.0, 1.0)))
    inside = 1.0 - _smoothstep(radius_deg * (1.0 - soft), radius_deg, angle)
    return inside[..., None] * np.asarray(radiance, dtype=np.float64)


def _window(x, lo, hi, soft):
    """1 on ``[lo, hi]``, 0 outside ``[lo - soft, hi + soft]``, smooth in between."""
    return _smoothstep(lo - soft, lo, x) * (1.0 - _smoothstep(hi, hi + soft, x))


def _box_light(w, phi_deg, elev_deg, radiance, soft_deg=2.0):
    """Rectangular lat-long 'softbox' spanning azimuths ``phi_deg`` and elevations ``elev_deg``."""
    phi = np.degrees(np.arctan2(w[..., 0], w[..., 2]))
    elev = np.degrees(np.arcsin(np.clip(w[..., 1], -1.0, 1.0)))
    inside = _window(phi, *phi_deg, soft_deg) * _window(elev, *elev_deg, soft_deg)
    return inside[..., None] * np.asarray(radiance, dtype=np.float64)


def procedural_sky(height: int = 64, width: int = 128) -> np.ndarray:
    """A small studio-like lat-long environment ``(height, width, 3)``.

    Sky: blue at the zenith fading to a pale horizon (radiance ~0.3-0.8); ground: a dark
    warm grey (~0.05-0.15); plus a warm rectangular key softbox (radiance 3, 50 x 35 deg)
    above-left on the viewer's side and a cool round rim light (radiance 2.5, 15 deg
    radius) low on the right behind the sphere. Contrasts are moderate so that a few tens
    of BRDF samples per pixel give clean images even for rough materials.

    Parameters
    ----------
    height, width : int
        Map size, texels.

    Returns
    -------
    (height, width, 3) ndarray
        Linear RGB radiance.

    Examples
    --------
    >>> sky = procedural_sky(32, 64)
    >>> sky.shape, bool((sky >= 0).all())
    ((32, 64, 3), True)
    """
    w = latlong_directions(height, width)
    y = w[..., 1:2]
    zenith, horizon = np.array([0.18, 0.32, 0.65]), np.array([0.75, 0.8, 0.85])
    ground_hi, ground_lo = np.array([0.16, 0.14, 0.12]), np.array([0.05, 0.045, 0.04])
    sky = horizon + (zenith - horizon) * np.sqrt(np.clip(y, 0.0, 1.0))
    ground = ground_lo + (ground_hi - ground_lo) * (1.0 - np.sqrt(np.clip(-y, 0.0, 1.0)))
    blend = _smoothstep(-0.03, 0.03, y)
    env = blend * sky + (1.0 - blend) * ground
    env = env + _box_light(w, (-75.0, -25.0), (20.0, 55.0), (3.0, 2.7, 2.3))
    env = env + _disk_light(w, (0.95, 0.25, -0.6), 15.0, (1.9, 2.3, 2.7))
    return env
