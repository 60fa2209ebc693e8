"""The sample grids of the tabulated measured formats, shared by their readers
(:mod:`.merl`, :mod:`.utia`) and their compiled loops (:mod:`._kernels`), which need them
as compile-time constants: here, so that neither imports the other.

* MERL (Matusik et al. 2003): ``(theta_h, theta_d, phi_d)`` bins :data:`MERL_SHAPE`,
  ``theta_h`` on a square-root axis, ``phi_d`` over ``[0, pi)`` (reciprocity).
* UTIA (Filip & Vavra 2014): ``[channel, theta_i, phi_i, theta_v, phi_v]`` samples
  :data:`UTIA_SHAPE`, ``theta = 0, 15, ..., 75`` degrees (:data:`UTIA_THETA_STEP`),
  ``phi = 0, 7.5, ..., 352.5`` degrees (:data:`UTIA_PHI_STEP`).

Example: ``MERL_SHAPE[0] * MERL_SHAPE[1] * MERL_SHAPE[2]`` is 1,458,000 samples per channel.

Examples
--------
>>> import math
>>> MERL_SHAPE, math.prod(MERL_SHAPE)
((90, 90, 180), 1458000)
>>> UTIA_SHAPE, round(math.degrees(UTIA_THETA_STEP), 9), round(math.degrees(UTIA_PHI_STEP), 9)
((3, 6, 48, 6, 48), 15.0, 7.5)
"""
from __future__ import annotations

import math

__all__ = ["MERL_SHAPE", "UTIA_SHAPE", "UTIA_THETA_STEP", "UTIA_PHI_STEP"]

MERL_SHAPE = (90, 90, 180)                     # (theta_h, theta_d, phi_d) bins
UTIA_SHAPE = (3, 6, 48, 6, 48)                 # [channel, theta_i, phi_i, theta_v, phi_v]
UTIA_THETA_STEP = math.radians(15.0)
UTIA_PHI_STEP = math.radians(7.5)
