#!/usr/bin/env python3
"""LEADR validation: Smith masking on real geometry (5b) and LEADR vs. naive MIP (5c).

**5b — Smith masking of Gaussian heightfields.** A periodic Gaussian random heightfield
with a prescribed slope covariance (``mf.leadr.gaussian_heightfield``, FFT synthesis) plus
a plane of prescribed mean slope is read as a *bilinear* surface over its texel grid.
Points are drawn uniformly on the macro plane and weighted by their front-facing
projected area toward ``k``, ``w = <k, n>+ / n_z = max(0, z_k - x_k h_x - y_k h_y)``; a
ray from each point toward ``k`` is traced exactly through the bilinear patches (DDA over
the cells, the ray-patch height difference is a quadratic in the ray parameter) and the
weighted unoccluded fraction estimates the masking ``E[V] = 1 / (1 + Lambda(k))``
(supplemental Eq. 8). The prediction is Smith's ``Lambda`` of the noncentral
anisotropic Beckmann distribution with the surface's own slope moments (computed exactly
for the bilinear surface: ``E[h_x^2] = (a^2 + a b + b^2) / 3`` over a cell with edge
differences ``a, b``, etc.). Standard errors are those of the weighted-ratio estimator
(the points' Monte Carlo error); several independent fields show the realization spread.

**5c — LEADR vs. naive MIP vs. supersampling.** See :mod:`microfacet.leadr.figures`: a
displaced patch shaded at MIP levels 1..6 under a directional light and an environment,
orthographic camera (constant directions, so only the NDF filtering differs), relative
RMS error of naive MIP and LEADR against the projected-area-weighted supersampled
reference. Two height maps: a single-scale Gaussian field (a Beckmann microgeometry) and
the structured map of the demo (bumps + grooves).

Usage::

    python experiments/leadr_validation.py [--quick] [--out experiments/results/leadr_validation.md]
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import platform
import time

import numba
import numpy as np

import microfacet as mf
from microfacet.geometry import spherical_to_cartesian
from microfacet.io import write_text
from microfacet.leadr import figures, gaussian_heightfield, shading


# --------------------------------------------------------------------------- 5b
def bilinear_moments(Z, mean_slope=(0.0, 0.0)) -> np.ndarray:
    """Exact slope moments ``(5,)`` of the periodic bilinear surface ``Z[row, col]``
    (heights in texel units, x along columns, y along rows) plus a plane of slope
    ``mean_slope``: per cell ``h_x = (1 - fy) a + fy b``, ``h_y = (1 - fx) c + fx d``."""
    z10, z01, z11 = (np.roll(Z, s, axis=(0, 1)) for s in ((0, -1), (-1, 0), (-1, -1)))
    a, b = z10 - Z, z11 - z01
    c, d = z01 - Z, z11 - z10
    mx, my = mean_slope
    ex, ey = np.mean(0.5 * (a + b)), np.mean(0.5 * (c + d))
    exx, eyy = np.mean((a * a + a * b + b * b) / 3.0), np.mean((c * c + c * d + d * d) / 3.0)
    exy = np.mean(0.25 * (a + b) * (c + d))
    return np.array([ex + mx, ey + my, exx + 2 * mx * ex + mx * mx, eyy + 2 * my * ey + my * my,
                     exy + mx * ey + my * ex + mx * my])


@numba.njit
def _height(Z, x, y):
    H, W = Z.shape
    i, j = math.floor(x), math.floor(y)
    fx, fy = x - i, y - j
    i0, j0, i1, j1 = i % W, j % H, (i + 1) % W, (j + 1) % H
    z00, z10, z01, z11 = Z[j0, i0], Z[j0, i1], Z[j1, i0], Z[j1, i1]
    hx = (1 - fy) * (z10 - z00) + fy * (z11 - z01)
    hy = (1 - fx) * (z01 - z00) + fx * (z11 - z10)
    h = z00 + fx * (z10 - z00) + fy * (z01 - z00) + fx * fy * (z11 - z10 - z01 + z00)
    return h, hx, hy


@numba.njit
def _visible(Z, zmax, mx, my, dx, dy, s, x0, y0, h0):
    """1 if the ray from ``(x0, y0)`` at relative height ``h0`` above the plane, horizontal
    direction ``(dx, dy)`` and rise ``s`` per unit length, escapes the bilinear surface."""
    H, W = Z.shape
    i, j = math.floor(x0), math.floor(y0)
    inf = 1e300
    sx = 1 if dx > 0 else -1
    sy = 1 if dy > 0 else -1
    tdx = abs(1.0 / dx) if dx != 0 else inf
    tdy = abs(1.0 / dy) if dy != 0 else inf
    tmx = ((i + 1 - x0) / dx if dx > 0 else (x0 - i) / -dx) if dx != 0 else inf
    tmy = ((j + 1 - y0) / dy if dy > 0 else (y0 - j) / -dy) if dy != 0 else inf
    rise = s - mx * dx - my * dy             # rise above the plane per unit length
    eps = 1e-12 * (1.0 + abs(h0))
    t0 = 0.0
    for _ in range(10_000_000):
        t1 = min(tmx, tmy)
        i0, j0, i1, j1 = i % W, j % H, (i + 1) % W, (j + 1) % H
        z00, z10, z01, z11 = Z[j0, i0], Z[j0, i1], Z[j1, i0], Z[j1, i1]
        a, c, e = z10 - z00, z01 - z00, z11 - z10 - z01 + z00
        fx0, fy0 = x0 - i, y0 - j
        # r(t) = ray - surface (both relative to the plane) = A + B t + C t^2
        A = h0 - (z00 + a * fx0 + c * fy0 + e * fx0 * fy0)
        B = rise - (a * dx + c * dy + e * (fx0 * dy + fy0 * dx))
        C = -e * dx * dy
        r1 = A + (B + C * t1) * t1
        lo = r1
        if t0 > 0:
            lo = min(lo, A + (B + C * t0) * t0)
        if C > 0:
            tv = -B / (2 * C)
            if t0 < tv < t1:
                lo = min(lo, A + (B + C * tv) * tv)
        if lo < -eps:
            return 0
        if h0 + rise * t1 > zmax:
            return 1
        if tmx < tmy:
            i += sx
            tmx += tdx
        else:
            j += sy
            tmy += tdy
        t0 = t1
    return 1


@numba.njit(parallel=True)
def _trace_all(Z, zmax, mx, my, k, xs, ys, w_out, v_out):
    kx, ky, kz = k[0], k[1], k[2]
    r = math.sqrt(kx * kx + ky * ky)
    dx, dy, s = kx / r, ky / r, kz / r
    for n in numba.prange(xs.shape[0]):
        h0, hx, hy = _height(Z, xs[n], ys[n])
        w = kz - kx * (hx + mx) - ky * (hy + my)
        w_out[n] = max(w, 0.0)
        v_out[n] = _visible(Z, zmax, mx, my, dx, dy, s, xs[n], ys[n], h0) if w > 0 else 0


def visible_fraction(Z, k, n_points: int, rng, mean_slope=(0.0, 0.0)) -> tuple[float, float]:
    """Ray-cast masking ``E[V](k)`` of the bilinear surface ``Z`` (texel units, periodic)
    plus a plane of slope ``mean_slope``, and its standard error (module docstring).
    ``k`` must not be vertical and must see the mesosurface (``c_k > 0``)."""
    H, W = Z.shape
    xs, ys = rng.uniform(0, W, n_points), rng.uniform(0, H, n_points)
    w, v = np.empty(n_points), np.empty(n_points, dtype=np.int64)
    _trace_all(np.ascontiguousarray(Z, dtype=np.float64), float(Z.max()), float(mean_slope[0]),
               float(mean_slope[1]), np.asarray(k, dtype=np.float64), xs, ys, w, v)
    g = float(np.sum(w * v) / np.sum(w))
    se = float(np.sqrt(np.sum(w * w * (v - g) ** 2)) / np.sum(w))
    return g, se


def masking_field(size: int, alpha_x, alpha_y, rho, correlation, seed) -> np.ndarray:
    """Periodic Gaussian heightfield in texel units (slopes per texel)."""
    return gaussian_heightfield((size, size), alpha_x, alpha_y, rho, correlation=correlation, seed=seed) * size


def predicted_masking(moments, k) -> float:
    """Smith ``1 / (1 + Lambda(k))`` of the Beckmann surface of ``moments``."""
    d = mf.leadr.from_moments(moments)
    return float(1.0 / (1.0 + d.lambda_(np.asarray(k, dtype=np.float64))))


SURFACES = {
    "isotropic α = 0.6": dict(alpha_x=0.6, alpha_y=0.6, rho=0.0, mean_slope=(0.0, 0.0)),
    "anisotropic α = (0.7, 0.3), ρ = 0.5": dict(alpha_x=0.7, alpha_y=0.3, rho=0.5, mean_slope=(0.0, 0.0)),
    "same, mean slope (0.3, -0.2)": dict(alpha_x=0.7, alpha_y=0.3, rho=0.5, mean_slope=(0.3, -0.2)),
}


def masking_table(size: int, correlation: float, n_points: int, seeds, thetas_deg, phis_deg):
    rows = []
    for name, p in SURFACES.items():
        for seed in seeds:
            Z = masking_field(size, p["alpha_x"], p["alpha_y"], p["rho"], correlation, seed)
            E = bilinear_moments(Z, p["mean_slope"])
            rng = np.random.default_rng(1000 + seed)
            for th in thetas_deg:
                for ph in phis_deg:
                    k = spherical_to_cartesian(np.radians(th), np.radians(ph))
                    c = k[2] - k[0] * E[0] - k[1] * E[1]
                    if c <= 0.02:
                        continue
                    g, se = visible_fraction(Z, k, n_points, rng, p["mean_slope"])
                    rows.append(dict(surface=name, seed=seed, theta=th, phi=ph, measured=g, se=se,
                                     predicted=predicted_masking(E, k)))
    return rows


def summarize_masking(rows, theta_max_moderate=70.0):
    out = []
    for name in SURFACES:
        for th in sorted({r["theta"] for r in rows}):
            sel = [r for r in rows if r["surface"] == name and r["theta"] == th]
            if not sel:
                continue
            err = np.array([r["predicted"] - r["measured"] for r in sel])
            z = np.array([(r["predicted"] - r["measured"]) / r["se"] for r in sel if r["se"] > 0])
            out.append(dict(surface=name, theta=th, n=len(sel), measured=np.mean([r["measured"] for r in sel]),
                            predicted=np.mean([r["predicted"] for r in sel]), mean_err=err.mean(),
                            max_abs_err=np.abs(err).max(), se=np.mean([r["se"] for r in sel]),
                            rms_z=float(np.sqrt(np.mean(z * z))) if z.size else float("nan")))
    return out


# --------------------------------------------------------------------------- 5c
def orthographic_scene(theta_o, phi_o, theta_i, phi_i) -> figures.PatchScene:
    """Directional light and orthographic camera (constant directions) as a PatchScene."""
    far = 1e6
    o = spherical_to_cartesian(np.radians(theta_o), np.radians(phi_o))
    i = spherical_to_cartesian(np.radians(theta_i), np.radians(phi_i))
    centre = np.array([0.5, 0.5, 0.0])
    return figures.PatchScene(camera=tuple(centre + far * o), light=tuple(centre + far * i), intensity=far**2)


BASE_ALPHA = 0.1
CONFIGS = {  # (theta_o, phi_o, theta_i, phi_i): view and light, degrees
    "near mirror, θo = 30°": (30, 180, 34, 0),
    "off-peak, θo = 30°": (30, 180, 50, 20),
    "grazing view, θo = 70°": (70, 180, 65, 10),
}


ENV_CONFIG = (53, 40, 30, 0)   # the reflection of the view hits the key softbox of the sky


def _errors(images, kind, lv):
    ref = images[kind, lv]["reference"]
    return {m: (figures.relative_rms(images[kind, lv][m], ref), float(images[kind, lv][m].mean() / ref.mean() - 1))
            for m in ("naive", "leadr")}


def shading_table(fields, levels, base=BASE_ALPHA):
    rows = []
    for fname, height in fields.items():
        for cname, cfg in CONFIGS.items():
            images, _ = figures.compare_levels(height, base, levels=levels, scene=orthographic_scene(*cfg),
                                               kinds=("point",))
            rows += [dict(field=fname, config=f"point light, {cname}", level=lv, **_errors(images, "point", lv))
                     for lv in levels]
        for grid, offset in ((5, None), (5, -1.48), (16, None)):
            scene = dataclasses.replace(orthographic_scene(*ENV_CONFIG), grid=grid, lod_offset=offset)
            images, _ = figures.compare_levels(height, base, levels=levels, scene=scene, kinds=("env",))
            lod = f"LOD constant {shading.lod_bias(grid) if offset is None else offset:+.2f}"
            rows += [dict(field=fname, config=f"environment, θo = 53°, {grid} x {grid} grid, {lod}", level=lv,
                          **_errors(images, "env", lv)) for lv in levels]
    return rows


# --------------------------------------------------------------------------- main
def run(quick: bool):
    t0 = time.perf_counter()
    if quick:
        mask = masking_table(256, 4.0, 20_000, seeds=(0,), thetas_deg=(45, 60, 75, 85), phis_deg=(0, 90))
    else:
        mask = masking_table(1024, 4.0, 200_000, seeds=(0, 1, 2),
                             thetas_deg=(30, 45, 60, 70, 75, 80, 85, 88), phis_deg=(0, 45, 90, 135, 180, 270))
    t_mask = time.perf_counter() - t0
    size = 128 if quick else 256
    fields = {"Gaussian (α = (0.5, 0.3), ρ = 0.3, corr. 4 texels)":
              gaussian_heightfield((size, size), 0.5, 0.3, 0.3, correlation=4.0, seed=7),
              "structured (demo: bumps + grooves)": figures.default_heightfield(size)}
    levels = (1, 2, 3, 4, 5) if quick else (1, 2, 3, 4, 5, 6)
    shade = shading_table(fields, levels)
    return mask, summarize_masking(mask), shade, t_mask, time.perf_counter() - t0 - t_mask


def report(mask, summary, shade, t_mask, t_shade, quick: bool) -> str:
    lines = ["# LEADR validation (5b masking on Gaussian heightfields, 5c LEADR vs. naive MIP)", "",
             f"{'Quick' if quick else 'Full'} run; {platform.machine()}, Python {platform.python_version()}, "
             f"NumPy {np.__version__}; masking {t_mask:.1f} s, shading {t_shade:.1f} s.", "",
             "## 5b. Smith masking on ray-cast Gaussian heightfields", "",
             "Measured: weighted unoccluded fraction of the front-facing projected area (exact ray / "
             "bilinear-patch intersection). Predicted: Smith 1/(1+Λ(k)) of the noncentral anisotropic "
             "Beckmann with the surface's exact bilinear slope moments. Per elevation: mean over azimuths "
             "and fields of predicted − measured, the largest |error|, the mean standard error of one "
             "measurement, and the RMS of the z-scores (error / standard error; ≈ 1 if the only error "
             "were the Monte Carlo error).", "",
             "| surface | θ (deg) | directions | measured | predicted | mean error | max abs error "
             "| mean s.e. | RMS z |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in summary:
        lines.append(f"| {r['surface']} | {r['theta']:g} | {r['n']} | {r['measured']:.4f} | {r['predicted']:.4f} | "
                     f"{r['mean_err']:+.4f} | {r['max_abs_err']:.4f} | {r['se']:.4f} | {r['rms_z']:.2f} |")
    lines += ["", "## 5c. LEADR vs. naive MIP against supersampling", "",
              "Each cell: relative RMS error over the image / relative error of the image mean, against "
              "the projected-area-weighted supersampled reference of the same resolution (level k: one "
              f"pixel per 2^k x 2^k texels). Base material Beckmann α = {BASE_ALPHA:g}, silver Fresnel; "
              "masking only; orthographic view, directional light. Point light: analytic formula; "
              "environment: filtered sample grid (the reference shades every texel with the same grid and "
              "LOD rule). The LOD constant of Sec. 3.5 is -1.48 unbiased; the supplemental raises it to "
              "+0.5 for 5 x 5 grids against banding (over-blurring, hence darkening, rough lobes here).", ""]
    levels = sorted({r["level"] for r in shade})
    lines.append("| height map | lighting | method | " + " | ".join(f"level {lv}" for lv in levels) + " |")
    lines.append("|---|---|---|" + "---|" * len(levels))
    keys = []
    for r in shade:
        if (r["field"], r["config"]) not in keys:
            keys.append((r["field"], r["config"]))
    for f, c in keys:
        for m in ("naive", "leadr"):
            vals = {r["level"]: r[m] for r in shade if r["field"] == f and r["config"] == c}
            lines.append(f"| {f} | {c} | {'naive MIP' if m == 'naive' else 'LEADR'} | "
                         + " | ".join(f"{100 * vals[lv][0]:.1f}% / {100 * vals[lv][1]:+.1f}%" for lv in levels)
                         + " |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small fields and few rays (seconds)")
    ap.add_argument("--out", default="experiments/results/leadr_validation.md")
    args = ap.parse_args(argv)
    mask, summary, shade, t_mask, t_shade = run(args.quick)
    text = report(mask, summary, shade, t_mask, t_shade, args.quick)
    write_text(args.out, text)
    print(text)


if __name__ == "__main__":
    main()
