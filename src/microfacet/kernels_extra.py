"""Ahead-of-time compilation of the compiled loops outside the Smith kernels: the measured-BRDF
readers' loops (:mod:`microfacet.measured`), the LEADR map and MIP kernels
(:mod:`microfacet.leadr`) and the glints kernels (:mod:`microfacet.glints`: microsurface build,
P-BRDF footprint loops, naive renderer). These compile at their first use (Numba ``cache=True``,
10-120 s on 2 cores, in every process that finds the cache empty); run here once, as
``make setup`` does, later processes load them from Numba's on-disk cache in milliseconds
(``docs/performance.md``).

Each group runs a small instance of the code path that uses it (the demo's LEADR and glints
sections on tiny maps, eval and sample of synthetic MERL, UTIA and RGL data), so the kernels are
compiled for exactly the argument types that the library passes them (those do not depend on the
sizes). Usage (the command line of :func:`microfacet.precompile.main`, restricted to these groups)::

    python -m microfacet.kernels_extra --precompile [--groups measured,leadr,glints] [-q]

Example: ``microfacet.kernels_extra.precompile(("leadr",))`` returns 1 (one group compiled or loaded).
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from . import kernels

__all__ = ["GROUPS", "group_calls", "precompile"]

#: The groups of kernels that :func:`precompile` compiles, in order (the slowest last).
GROUPS = ("measured", "leadr", "glints")


def _measured() -> None:
    """eval, eval_cos and sample of synthetic MERL, UTIA and RGL BRDFs (their readers' loops:
    ``eval_table``/``sample_table``, ``eval_rgl``/``sample_rgl``), rows of directions as every
    caller passes them (the readers copy their inputs to C-contiguous float64 rows)."""
    from .measured.merl import SHAPE as MERL_SHAPE
    from .measured.merl import MERLBRDF
    from .measured.rgl import RGLBRDF
    from .measured.utia import SHAPE as UTIA_SHAPE
    from .measured.utia import UTIABRDF
    rng = np.random.default_rng(0)
    n = 8
    wo = np.tile([0.0, 0.6, 0.8], (n, 1))
    wi = np.tile([0.6, 0.0, 0.8], (n, 1))
    u = rng.random((n, 2))
    brdfs = [MERLBRDF(np.full(MERL_SHAPE + (3,), 0.1), np.ones(MERL_SHAPE, bool)),
             UTIABRDF(np.full(UTIA_SHAPE[1:] + (3,), 0.1)), RGLBRDF(synthetic_rgl(rng))]
    for b in brdfs:
        b.eval(wi, wo)
        b.eval_cos(wi, wo)
        b.sample(u, wo)


def synthetic_rgl(rng, phi_i=(0.0,), n_theta: int = 4) -> dict:
    """The fields of a small, smooth, positive RGL ``.bsdf`` file (``phi_i`` slices), as
    :func:`microfacet.measured.rgl.read_rgl` returns them (float32 tables)."""
    phi_i = np.asarray(phi_i, np.float32)
    theta_i = np.linspace(0, np.pi / 2 * 0.9, n_theta).astype(np.float32)
    n_phi = len(phi_i)
    s = np.linspace(0, 1, 16)
    bump = np.exp(-(s[:, None] ** 2 + s[None, :] ** 2) / 0.3)

    def table(*shape):
        return (rng.uniform(0.5, 1.5, shape) * 0.2 + 1.0).astype(np.float32)
    return {
        "version": np.array([1, 0], np.uint32),
        "description": np.frombuffer(b"synthetic material", np.uint8),
        "phi_i": phi_i, "theta_i": theta_i,
        "sigma": np.repeat(np.linspace(1.0, 0.4, 32)[None], 2, 0).astype(np.float32),
        "ndf": np.repeat(np.exp(-np.linspace(0, 1, 32) ** 2 * 6)[None] * 3, 2, 0).astype(np.float32),
        "vndf": (table(n_phi, n_theta, 16, 16) * bump).astype(np.float32),
        "luminance": table(n_phi, n_theta, 8, 8),
        "rgb": (table(n_phi, n_theta, 3, 8, 8) - 0.15).astype(np.float32),
        "jacobian": np.array([1], np.uint8),
        "valid": np.ones(8, np.uint8),
    }


def _leadr() -> None:
    """The demo's LEADR section on a 16^2 height map (height moments, MIP reductions), and
    ``microfacet bake`` of a 16-bit PNG height map (integer heights into the pyramid's levels)."""
    from .batch.tasks import bake_file
    from .io.png import write_png_data
    from .leadr.figures import leadr_section
    with tempfile.TemporaryDirectory(prefix="microfacet-precompile-") as d:
        leadr_section(d, size=16, levels=(1, 2), display=16)
        y, x = np.mgrid[0:16, 0:16] / 16.0
        height = write_png_data(Path(d) / "height.png", np.round(
            (0.5 + 0.25 * np.sin(2 * np.pi * x) * np.cos(2 * np.pi * y)) * 65535).astype(np.uint16))
        bake_file(height, Path(d) / "height.exr")


def _glints() -> None:
    """The demo's glints section on a 32^2 normal map and an 8-pixel plane (microsurface build,
    P-BRDF footprint loops exact and approximate, naive renderer, white furnace), and a
    microsurface file written and read back (the Mitsuba glints plugin), ``microfacet glints`` of an
    8-bit PNG normal map."""
    from .batch.tasks import glints_file
    from .glints import Microsurface
    from .glints.figures import glints_section, scratched_normal_map
    from .io.png import write_png_data
    with tempfile.TemporaryDirectory(prefix="microfacet-precompile-") as d:
        glints_section(d, map_size=32, width=8, reference_spp=2, naive_spp=1)
        normals = scratched_normal_map(32, scratches=4, seed=0)
        ms = Microsurface.from_normal_map(normals)
        Microsurface.load(ms.save(Path(d) / "microsurface.npz"))
        patch = ms.pbrdf((0.37, 0.61), np.eye(2) * (2.0 / 32) ** 2)     # a P-BRDF's protocol (Mitsuba, sweeps)
        wo = np.tile([0.0, 0.6, 0.8], (8, 1))
        patch.eval_cos(np.tile([0.6, 0.0, 0.8], (8, 1)), wo)
        patch.sample(np.random.default_rng(0).random((8, 2)), wo)
        png = write_png_data(Path(d) / "normals.png", np.round((normals + 1.0) * 127.5).astype(np.uint8))
        glints_file(png, Path(d) / "glints.npz")                    # microfacet glints of an 8-bit PNG


_CALLS = {"measured": _measured, "leadr": _leadr, "glints": _glints}


def group_calls(groups=GROUPS) -> list:
    """``[(group, call)]`` of :func:`precompile`; ``ValueError`` for an unknown group.

    Parameters
    ----------
    groups : sequence of str
        Names in :data:`GROUPS`.

    Returns
    -------
    list of (str, callable)
        The group and its compile call.

    Examples
    --------
    >>> GROUPS
    ('measured', 'leadr', 'glints')
    >>> [group for group, call in group_calls(("measured", "leadr"))]
    ['measured', 'leadr']
    >>> group_calls(["brdf"])
    Traceback (most recent call last):
        ...
    ValueError: groups must be among measured, leadr, glints, got brdf
    """
    bad = [g for g in groups if g not in _CALLS]
    if bad:
        raise ValueError(f"groups must be among {', '.join(GROUPS)}, got {', '.join(map(str, bad))}")
    return [(g, _CALLS[g]) for g in groups]


def precompile(groups=GROUPS, progress=None) -> int:
    """Compiles the kernels of ``groups`` (:data:`GROUPS`) into Numba's on-disk cache, or loads
    those already there, one group after the other in this process
    (:func:`microfacet.kernels.precompile_calls`: compiling the same function in two processes at
    once can corrupt Numba's cache index). ``progress(group, seconds)`` is called after each.
    Returns how many groups ran; 0 without Numba (or with ``MICROFACET_NUMBA=0``). The command
    line is :func:`microfacet.precompile.main`'s.

    Parameters
    ----------
    groups : sequence of str
        Names in :data:`GROUPS`.
    progress : callable, optional
        ``progress(group, seconds)``.

    Returns
    -------
    int
        Groups run.

    Examples
    --------
    >>> precompile(groups=())       # no group: nothing to compile
    0
    >>> precompile(groups=("measured",))   # compiles for minutes when cold  # doctest: +SKIP
    """
    return kernels.precompile_calls(group_calls(groups), progress)


if __name__ == "__main__":    # python -m microfacet.kernels_extra --precompile: the one entry point, these groups
    from microfacet.kernels_extra import GROUPS as _GROUPS
    from microfacet.precompile import main
    raise SystemExit(main(prog="python -m microfacet.kernels_extra", groups=_GROUPS))
