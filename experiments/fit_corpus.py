#!/usr/bin/env python3
"""Fit every material of the shared corpus with the CLI's defaults and report how the
fits look: ``experiments/results/fit_corpus.md`` (+ ``.json``, ``.csv``) and contact sheets
of spheres ``experiments/results/fit_corpus_*.png``.

Corpus: every Neural-BRDF network of ``DATA/nbrdf/{merl,rgl,nielsen}/*.npz`` (Sztrajman et
al. 2021; 119 materials), converted once by ``../shared/tools/nbrdf_to_merl.py`` into a
cache folder as MERL-format files named as ``tests/conftest.py``'s ``corpus_file``
(``{group}__{name}.binary``), plus the real RGL measurements ``DATA/rgl/*.bsdf`` (group
``rgl_real``).

Phases (``--phase``, default ``all`` = convert, baseline, fit, evaluate, report):

* ``convert``: the MERL-format files (cached; atomic writes).
* ``baseline``: "today's default", the CLI's headline fit before issue 24 (the ``"ggx"``
  entry of ``OUT.json`` written by commit 416aa6c), run in a subprocess from a worktree of
  that commit (``git worktree add /tmp/mf-baseline 416aa6c``; ``--baseline-tree``), cached
  in ``WORK/baseline/`` (that code never changes, so it is never rerun unless ``--force``).
* ``fit``: :func:`microfacet.batch.tasks.fit_file` (what ``microfacet fit FILE -o OUT.npz``
  runs, with every option at its default; no picture), into ``WORK/fits/``; a material is
  refitted only if its ``OUT.json`` is older than the fit code (``src/microfacet/fit/*.py``)
  or with ``--force``. The phase's wall time with ``--jobs`` processes is the corpus time.
* ``evaluate``: every fit of the fit file (each name of ``summary["fits"]`` through
  ``microfacet.fit.load(path, model=NAME)``; with a fit file of the older format, the
  tabulated fit and the JSON's ``"ggx"``/``"beckmann"`` entries), the ABC fit of Löw et
  al. 2012 (MERL materials) and the baseline, all scored against the data with the current
  metrics (below); results in ``WORK/results/KEY.json`` (redone when older than the fit,
  the baseline, this script or the metrics code).
* ``report``: the results page, its JSON and CSV, the contact sheets.

Metrics per fit (the data is the reference; grazing pairs ``cos < 0.1`` excluded):

* ``grid``, ``uniform``: :class:`microfacet.metrics.RelativeRMS` of ``f cos`` over
  :func:`~microfacet.metrics.measurement_directions` and
  :func:`~microfacet.metrics.uniform_directions`;
* ``log``: the cosine-weighted log error (:class:`microfacet.metrics.LogError` when the
  library has it, else :func:`log_error_fallback`);
* ``image``: the rendered-sphere image error (:class:`microfacet.metrics.ImageError` when
  the library has it, else :func:`image_error_fallback`);
* ``albedo``: directional albedo fit/data at 0/30/60/75 deg
  (:class:`~microfacet.metrics.AlbedoRatios`); ``albedo_worst`` is the ratio farthest from
  1 over views and the channels whose data albedo exceeds 0.03;
* ``furnace``: :func:`~microfacet.metrics.white_furnace` (for ABC: the same quadrature of
  its specular term with F = 1);
* ``chroma``: the largest difference of rgb chromaticity ``(r, g, b) / (r + g + b)`` of the
  mean colour of the rendered spheres (directional light and environment), fit vs data;
* ``fresnel_tv``: for each tabulated Fresnel term in the fit, per channel total variation
  ``sum |diff|`` over its range ``max - min``; the worst channel and table.

Per material, of the data: ``fold_seam`` (:meth:`~microfacet.measured.MERLBRDF.fold_seam`)
and ``data_albedo_off_normal``, the albedo :data:`OFF_NORMAL_DEG` off the normal
(:func:`normal_jump` compares it with the albedo at 0 deg).

Usage::

    python experiments/fit_corpus.py [--jobs 2] [--only NAME ...] [--phase all]
        [--data ../shared/data] [--cache ~/.cache/microfacet/corpus]
        [--work ~/.cache/microfacet/fit_corpus] [--baseline-tree /tmp/mf-baseline] [--force]

``NAME`` matches ``group/name``, ``name`` or a shell pattern of either (``merl/*paint*``).
A material that fails (conversion, fit or evaluation) gets a row with its error; the run
goes on.
"""
from __future__ import annotations

import argparse
import concurrent.futures
import csv
import datetime
import fnmatch
import io
import json
import multiprocessing
import os
import platform
import subprocess
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("MICROFACET_DATA") or ROOT.parent / "shared" / "data")
_CACHE_HOME = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "microfacet"
CACHE = Path(os.environ.get("MICROFACET_CORPUS_CACHE") or _CACHE_HOME / "corpus")
WORK = _CACHE_HOME / "fit_corpus"
BASELINE_COMMIT = "416aa6c"
BASELINE_TREE = Path("/tmp/mf-baseline")
RESULTS = ROOT / "experiments" / "results"
GROUPS = ("merl", "rgl", "nielsen")
REAL_RGL = "rgl_real"
#: View (deg) of the data's albedo next to normal view (``data_albedo_off_normal``).
OFF_NORMAL_DEG = 1.0
#: Albedo goal: within 5 % at every view, channels whose data albedo exceeds this.
ALBEDO_FLOOR = 0.03
ALBEDO_TOL = 0.05
CHROMA_TOL = 0.02
#: Fresnel-table goal: total variation <= TV_FACTOR x range (a table with one hump scores
#: exactly 2, up to rounding: a relative 1e-6 is allowed).
TV_FACTOR = 2.0
#: Contact-sheet sphere size (pixels) and rows per page.
SHEET_SIZE = 48
SHEET_ROWS = 26
#: Environment renders: samples per pixel of the fallback renderer.
ENV_SPP = 64


# --------------------------------------------------------------------------- corpus
@dataclass(frozen=True)
class Material:
    """A corpus material: ``group`` (merl, rgl, nielsen, rgl_real), ``name``, the network
    (``net``, None for a real RGL file) and the measured-BRDF file fitted (``file``)."""
    group: str
    name: str
    net: Path | None
    file: Path

    @property
    def key(self) -> str:
        return f"{self.group}__{self.name}"

    @property
    def label(self) -> str:
        return f"{self.group}/{self.name}"


def corpus(data: Path, cache: Path) -> list[Material]:
    """Every corpus network (converted file in ``cache``) and real RGL file of ``data``."""
    out = [Material(g, p.stem, p, cache / f"{g}__{p.stem}.binary")
           for g in GROUPS for p in sorted((data / "nbrdf" / g).glob("*.npz"))]
    out += [Material(REAL_RGL, p.stem, None, p) for p in sorted((data / "rgl").glob("*.bsdf"))]
    return out


def select(materials: list[Material], only) -> list[Material]:
    """The materials matching any pattern of ``only`` (``group/name`` or ``name``)."""
    if not only:
        return materials
    keep = [m for m in materials if any(fnmatch.fnmatch(m.label, p) or fnmatch.fnmatch(m.name, p) for p in only)]
    if not keep:
        raise SystemExit(f"--only {' '.join(only)}: no corpus material matches")
    return keep


def convert(m: Material, tool: Path) -> Path:
    """``m.file``, converted from ``m.net`` by ``tool`` on first use, atomically (the same
    convention as ``tests/conftest.py``'s ``corpus_file``)."""
    if m.net is None or m.file.is_file():
        return m.file
    m.file.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=m.file.parent, suffix=".binary")
    os.close(fd)
    try:
        subprocess.run([sys.executable, str(tool), str(m.net), "-o", tmp], check=True, capture_output=True)
        os.replace(tmp, m.file)
    finally:
        Path(tmp).unlink(missing_ok=True)
    return m.file


# ------------------------------------------------------------------------ ABC (Löw 2012)
def read_abc(csv_path: Path) -> dict[str, dict]:
    """Löw et al. 2012's ABC parameters per MERL material (``../shared/data/anchors``)."""
    with open(csv_path, newline="") as f:
        rows = list(csv.DictReader(f))
    return {r["material"]: {"kd": [float(r[f"kd_{c}"]) for c in "rgb"], "A": [float(r[f"A_{c}"]) for c in "rgb"],
                            "B": float(r["B"]), "C": float(r["C"]), "ior": float(r["ior"])} for r in rows}


def _unpolarized(c, n):
    """Unpolarized dielectric Fresnel reflectance of index ``n`` at ``cos theta_d = c``."""
    g = np.sqrt(np.maximum(n * n + c * c - 1.0, 0.0))
    t1, t2 = c * (g + c) - 1.0, c * (g - c) + 1.0
    return 0.5 * ((g - c) / (g + c)) ** 2 * (1.0 + (t1 / t2) ** 2)


class LocalABC:
    """The ABC BRDF of Löw et al. 2012 as dj_brdf evaluates it (``../shared/data/README.md``):
    ``f = kd/pi + F(ior; i.h) D G / (pi cos_i cos_o)``, ``D = A / (1 + B (1 - cos_h))^C``,
    ``G = min(1, 2 cos_h cos_i / (i.h), 2 cos_h cos_o / (o.h))``. Used until
    ``microfacet.anchors`` provides it. Sampling (for environment renders): a one-sample
    mixture of the cosine warp and of ``D``'s exact inverse CDF in ``u = 1 - cos_h``
    (density ``(1 + B u)^-C``, uniform azimuth), the mixture pdf in the weight.

    >>> abc = LocalABC(read_abc(DATA / "anchors" / "abc_low2012_merl.csv")["nickel"])
    """

    def __init__(self, p: dict, white: bool = False):
        self.p = p
        self.kd = np.zeros(3) if white else np.asarray(p["kd"], float)
        self.A = np.asarray(p["A"], float)
        self.B, self.C, self.ior, self.white = float(p["B"]), float(p["C"]), float(p["ior"]), white
        c1 = 1.0 - self.C
        if abs(c1) < 1e-6:
            self.norm = np.log1p(self.B) / self.B                       # int_0^1 (1 + B u)^-C du
        else:
            self.norm = np.expm1(c1 * np.log1p(self.B)) / (self.B * c1)
        if not white:
            from microfacet.metrics import directional_albedo
            spec = float(np.max(directional_albedo(LocalABC(p, white=True), (0.0,))))
            kd = float(np.mean(self.kd))
            self.p_diffuse = kd / (kd + spec) if kd + spec > 0 else 0.5

    def eval_cos(self, wi, wo, out=None):
        wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
        zi, zo = wi[..., 2], wo[..., 2]
        ok = (zi > 0) & (zo > 0)
        h = wi + wo
        h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
        ih = np.clip(np.sum(wi * h, -1), 1e-12, 1.0)
        oh = np.clip(np.sum(wo * h, -1), 1e-12, 1.0)
        ch = h[..., 2]
        F = 1.0 if self.white else _unpolarized(ih, self.ior)
        G = np.minimum(1.0, np.minimum(2 * ch * zi / ih, 2 * ch * zo / oh))
        D = self.A / (1.0 + self.B * (1.0 - ch))[..., None] ** self.C
        with np.errstate(divide="ignore", invalid="ignore"):
            spec = (F * G / (np.pi * np.where(ok, zo, 1.0)))[..., None] * D     # F D G cos_i / (pi cos_i cos_o)
        f = spec + (self.kd / np.pi) * zi[..., None]
        return np.where(ok[..., None], f, 0.0)

    def eval(self, wi, wo, out=None):
        zi = np.asarray(wi, float)[..., 2:3]
        return np.divide(self.eval_cos(wi, wo), zi, out=np.zeros_like(self.eval_cos(wi, wo)), where=zi > 0)

    def _pdf_h(self, ch):
        return (1.0 + self.B * (1.0 - ch)) ** -self.C / (self.norm * 2.0 * np.pi)

    def pdf(self, wi, wo, out=None):
        wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
        h = wi + wo
        h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
        oh = np.sum(wo * h, -1)
        ok = (wi[..., 2] > 0) & (wo[..., 2] > 0) & (oh > 0)
        spec = self._pdf_h(h[..., 2]) / (4.0 * np.maximum(oh, 1e-12))
        diff = np.maximum(wi[..., 2], 0.0) / np.pi
        return np.where(ok, self.p_diffuse * diff + (1.0 - self.p_diffuse) * spec, 0.0)

    def sample(self, u, wo, out=None):
        from microfacet.geometry import square_to_cosine_hemisphere
        u = np.asarray(u, float)
        wo = np.asarray(wo, float)
        shape = np.broadcast_shapes(u.shape[:-1], wo.shape[:-1])
        u, wo = np.broadcast_to(u, shape + (2,)), np.broadcast_to(wo, shape + (3,))
        pd = self.p_diffuse
        diffuse = u[..., 0] < pd
        u0 = np.where(diffuse, u[..., 0] / max(pd, 1e-12), (u[..., 0] - pd) / max(1.0 - pd, 1e-12))
        u0 = np.clip(u0, 0.0, 1.0 - 1e-12)
        wi_d = square_to_cosine_hemisphere(np.stack([u0, u[..., 1]], -1))
        c1 = 1.0 - self.C                                    # inverse CDF of (1 + B t)^-C on [0, 1]
        if abs(c1) < 1e-6:
            t = np.expm1(u0 * np.log1p(self.B)) / self.B
        else:
            t = np.expm1(np.log1p(u0 * np.expm1(c1 * np.log1p(self.B))) / c1) / self.B
        ch = np.clip(1.0 - t, 0.0, 1.0)
        sh = np.sqrt(np.maximum(0.0, 1.0 - ch * ch))
        phi = 2.0 * np.pi * u[..., 1]
        h = np.stack([sh * np.cos(phi), sh * np.sin(phi), ch], -1)
        oh = np.sum(wo * h, -1)
        wi_s = 2.0 * oh[..., None] * h - wo
        wi = np.where(diffuse[..., None], wi_d, wi_s)
        pdf = self.pdf(wi, wo)
        ok = (pdf > 0) & (wi[..., 2] > 0) & (wo[..., 2] > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            weight = np.where(ok[..., None], self.eval_cos(wi, wo) / np.where(ok, pdf, 1.0)[..., None], 0.0)
        return wi, weight, np.where(ok, pdf, 0.0)


def abc_models(data: Path) -> dict:
    """``{material: ABC BRDF}`` for the MERL materials: ``microfacet.anchors`` when the library
    has it, else :class:`LocalABC` from the CSV."""
    path = data / "anchors" / "abc_low2012_merl.csv"
    try:
        from microfacet import anchors
        fits = anchors.abc_fits(path)
        if isinstance(fits, dict) and fits:
            return fits
    except (ImportError, AttributeError):
        pass
    return {k: LocalABC(p) for k, p in read_abc(path).items()}


def abc_source() -> str:
    try:
        from microfacet import anchors  # noqa: F401
        return "microfacet.anchors"
    except ImportError:
        return "local evaluator (fit_corpus.LocalABC)"


def abc_white_furnace(params: dict) -> float:
    """Largest directional albedo over views 0-89 deg of the ABC model's specular term with
    F = 1 (its parameters ``params`` of :func:`read_abc`), as
    :func:`microfacet.metrics.white_furnace` measures microfacet lobes. ABC's ``D`` is not
    normalized, so this may exceed 1."""
    from microfacet.metrics import directional_albedo
    views = (0.0, 30.0, 60.0, 75.0, 85.0, 89.0)
    return float(np.max(directional_albedo(LocalABC(params, white=True), views)))


# ------------------------------------------------------------------------ fit files
def fit_code_mtime() -> float:
    """Latest modification time of the fit code (``src/microfacet/fit/*.py``)."""
    return max(p.stat().st_mtime for p in (ROOT / "src" / "microfacet" / "fit").rglob("*.py"))


def load_fits(out_npz: Path) -> tuple[dict, str, dict, dict]:
    """``(fits by name, best name, summary, load errors by name)`` of a fit file: every fit of
    ``summary["fits"]`` by ``microfacet.fit.load(path, model=NAME)`` (the new format), else
    the tabulated fit and the JSON's ``"ggx"``/``"beckmann"`` entries (best: ``"ggx"``, the
    CLI's headline fit)."""
    import microfacet as mf
    from microfacet.fit.outputs import analytic_from_json
    summary = json.loads(out_npz.with_suffix(".json").read_text())
    fits, errors = {}, {}
    if "fits" in summary:
        best = summary.get("best")
        for name in summary["fits"]:
            try:
                fits[name] = mf.fit.load(out_npz, model=name)
            except Exception as e:                       # noqa: BLE001 - recorded per fit
                errors[name] = f"{type(e).__name__}: {e}"
        return fits, best, summary, errors
    fits["tabulated"] = mf.fit.load(out_npz)
    for name in ("ggx", "beckmann"):
        try:
            fits[name] = analytic_from_json(summary[name])
        except Exception as e:                           # noqa: BLE001
            errors[name] = f"{type(e).__name__}: {e}"
    return fits, "ggx", summary, errors


# ----------------------------------------------------------------------- rendering
def _environment():
    from microfacet.render import Environment, procedural_sky
    return Environment(procedural_sky())


def render_pair(brdf, size: int, spp: int = ENV_SPP, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Linear RGB spheres ``(size, size, 3)`` of ``brdf``: under the comparison pictures'
    directional light and under the procedural studio environment (BRDF importance
    sampling, ``spp`` randomized Sobol' samples per pixel, a fixed seed)."""
    from microfacet.render import Sphere, render_sphere, shade_environment
    directional = render_sphere(brdf, size)
    sphere = Sphere(size, supersample=2)
    env = shade_environment(brdf, sphere.wo, sphere.frame, _environment(), spp, np.random.default_rng(seed))
    env = sphere.image(np.nan_to_num(env, nan=0.0, posinf=0.0, neginf=0.0))
    return directional, env


def renders(named: dict, size: int, reference=None) -> dict:
    """``{name: (directional, environment)}`` images for the contact sheets: the 45-degree
    light and the environment of ``microfacet.metrics.render_images`` (pairs the data
    ``reference`` has not measured black, as the image error compares them) when the
    library has it, else :func:`render_pair`."""
    try:
        from microfacet.metrics import render_images
    except ImportError:
        render_images = None
    out = {}
    for name, brdf in named.items():
        if render_images is not None:
            imgs = render_images(brdf, size=size, reference=reference)
            out[name] = (imgs[1], imgs[-1])
        else:
            out[name] = render_pair(brdf, size)
    return out


def chromaticity(images) -> np.ndarray:
    """rgb chromaticity ``(r, g, b) / (r + g + b)`` of the summed pixels of ``images``."""
    total = sum(np.nansum(np.asarray(i, float).reshape(-1, 3), axis=0) for i in images)
    s = float(np.sum(total))
    return total / s if s > 0 else np.full(3, 1.0 / 3.0)


# ------------------------------------------------------------------------- metrics
def log_error_fallback(wi, wo, w, ref):
    """Cosine-weighted log error (Löw et al. 2012, Eq. 10 style), over the weighted uniform
    pairs: ``sqrt(sum w (ln(1 + f_fit cos) - ln(1 + f_ref cos))^2 / sum w)``, RGB mean."""
    lref = np.log1p(np.maximum(ref, 0.0))

    def score(brdf):
        f = np.nan_to_num(np.asarray(brdf.eval_cos(wi, wo), float), nan=0.0, posinf=1e6)
        d = (np.log1p(np.maximum(f, 0.0)) - lref) ** 2
        return float(np.sqrt(np.sum(w[:, None] * d) / (3.0 * np.sum(w))))
    return score


def image_error_fallback(ref_images):
    """Relative RMS over the pixels of the rendered spheres (directional + environment)."""
    ref = np.concatenate([np.asarray(i, float).ravel() for i in ref_images])
    norm = float(np.sqrt(np.sum(ref * ref)))

    def score(images):
        fit = np.concatenate([np.asarray(i, float).ravel() for i in images])
        return float(np.sqrt(np.sum((fit - ref) ** 2))) / norm
    return score


def metric_sources() -> dict:
    import microfacet.metrics as mm
    return {"log": "microfacet.metrics.LogError" if hasattr(mm, "LogError") else "fit_corpus.log_error_fallback",
            "image": "microfacet.metrics.ImageError" if hasattr(mm, "ImageError") else
            "fit_corpus.image_error_fallback",
            "render": "microfacet.metrics.render_images" if hasattr(mm, "render_images") else "fit_corpus.render_pair",
            "abc": abc_source()}


def fresnel_tables(brdf, seen=None) -> list:
    """The tabulated Fresnel terms inside a BRDF tree (``fresnel``, ``brdfs``, ``coat``,
    ``base``, ``lobes``, ``parts``, ``specular`` attributes)."""
    from microfacet.fresnel import Tabulated
    seen = set() if seen is None else seen
    if id(brdf) in seen or brdf is None:
        return []
    seen.add(id(brdf))
    if isinstance(brdf, Tabulated):
        return [brdf]
    out = []
    for attr in ("fresnel", "coat", "base", "specular"):
        child = getattr(brdf, attr, None)
        if child is not None and not callable(getattr(type(brdf), attr, None)):
            out += fresnel_tables(child, seen)
    for attr in ("brdfs", "lobes", "parts"):
        for child in getattr(brdf, attr, None) or ():
            out += fresnel_tables(child, seen)
    return out


def tv_ratio(table) -> float:
    """Worst channel of total variation ``sum |diff|`` over range ``max - min`` of a table
    (0 for a constant channel)."""
    v = np.asarray(table.values, float)
    tv = np.sum(np.abs(np.diff(v, axis=0)), axis=0)
    rng = np.ptp(v, axis=0)
    r = np.where(rng > 1e-9, tv / np.maximum(rng, 1e-300), 0.0)
    return float(np.max(r))


def normal_jump(at_normal, off_normal) -> float | None:
    """The data's albedo at normal view over its albedo :data:`OFF_NORMAL_DEG` off it
    (``data_albedo`` row 0 over ``data_albedo_off_normal``), the channel farthest from 1 of
    those above :data:`ALBEDO_FLOOR`: about 1 for a table continuous there; not for one
    that jumps across its ``phi_d`` fold, where every light at normal view reads
    ``phi_d = 0`` and, off it, half of them read the other side."""
    if not at_normal or not off_normal:
        return None
    a, b = np.asarray(at_normal[0], float), np.asarray(off_normal, float)
    keep = (a > ALBEDO_FLOOR) & (b > 0)
    if not np.any(keep):
        return None
    r = a[keep] / b[keep]
    return float(r[np.argmax(np.abs(r - 1.0))])


def albedo_worst(ratios, ref_albedo) -> float:
    """Ratio farthest from 1 over views and the channels whose data albedo > ALBEDO_FLOOR."""
    r = np.asarray(ratios, float)
    keep = (np.asarray(ref_albedo, float) > ALBEDO_FLOOR) & np.isfinite(r)
    if not np.any(keep):
        return float("nan")
    r = r[keep]
    return float(r[np.argmax(np.abs(r - 1.0))])


def evaluate(m: Material, work: Path, abc, abc_params: dict | None = None, size: int = SHEET_SIZE) -> dict:
    """Every fit of ``m``'s fit file, its ABC fit (``abc``, MERL; parameters ``abc_params``)
    and the baseline, scored against the data; also writes the contact-sheet renders
    ``WORK/renders/KEY.npz``."""
    import microfacet as mf
    import microfacet.metrics as mm
    from microfacet.fit.outputs import analytic_from_json
    row: dict = {"group": m.group, "name": m.name, "key": m.key, "errors": {}}
    data = mf.measured.load(m.file)
    fit_path = work / "fits" / f"{m.key}.npz"
    fits, best, summary = {}, None, {}
    if fit_path.with_suffix(".json").is_file():
        fits, best, summary, errs = load_fits(fit_path)
        row["errors"].update(errs)
        row["fit_seconds"] = summary.get("seconds", 0.0) + summary.get("seconds_least_squares", 0.0)
        row["format"] = "fits" if "fits" in summary else "legacy"
    err_file = work / "fits" / f"{m.key}.error.json"
    if err_file.is_file() and not fit_path.with_suffix(".json").is_file():
        row["errors"]["fit"] = json.loads(err_file.read_text())["error"]
    wall = work / "fits" / f"{m.key}.wall.json"
    if wall.is_file():
        row["wall_seconds"] = json.loads(wall.read_text())["seconds"]
    row["best"] = best
    row["balanced_from"] = summary.get("fits", {}).get(best, {}).get("balanced_from") if fits else None
    row["fold_seam"] = data.fold_seam() if hasattr(data, "fold_seam") else None
    named = dict(fits)
    if abc is not None:
        named["abc"] = abc
    base_json = work / "baseline" / f"{m.key}.json"
    if base_json.is_file():
        try:
            named["baseline"] = analytic_from_json(json.loads(base_json.read_text())["ggx"])
        except Exception as e:                           # noqa: BLE001
            row["errors"]["baseline"] = f"{type(e).__name__}: {e}"
    elif (work / "baseline" / f"{m.key}.error.json").is_file():
        row["errors"]["baseline"] = json.loads((work / "baseline" / f"{m.key}.error.json").read_text())["error"]
    if not named:
        return row
    grid = mm.RelativeRMS(data, mm.measurement_directions())
    uniform = mm.RelativeRMS(data, mm.uniform_directions())
    albedo = mm.AlbedoRatios(data)
    ref_albedo = albedo.ref
    if hasattr(mm, "LogError"):
        log_metric = mm.LogError(data)
    else:
        log_metric = log_error_fallback(uniform.wi, uniform.wo, np.ravel(uniform.w), uniform.ref)
    shown = ["data", *dict.fromkeys(k for k in (best, "tabulated", "abc") if k in named)]
    images = renders({k: data if k == "data" else named[k] for k in shown}, size, data)
    if hasattr(mm, "ImageError"):
        image_metric = mm.ImageError(data)

        def image_and_chroma(name, brdf):
            d = image_metric.details(brdf)
            return d["image"], d["chromaticity"], d.get("per_image")
    else:
        own = {"data": images.get("data") or render_pair(data, size)}
        image_fallback = image_error_fallback(own["data"])
        chroma_data = chromaticity(own["data"])

        def image_and_chroma(name, brdf):
            imgs = images.get(name) or render_pair(brdf, size)
            return image_fallback(imgs), float(np.max(np.abs(chromaticity(imgs) - chroma_data))), None
    g, u = grid(named), uniform(named)
    per = {}
    for name, brdf in named.items():
        rec = {}
        try:
            a = albedo(brdf)
            image, chroma, per_image = image_and_chroma(name, brdf)
            rec.update(grid=g[name], uniform=u[name], log=float(log_metric(brdf)), image=float(image),
                       image_per_light=per_image, albedo=np.round(a, 4).tolist(),
                       albedo_worst=albedo_worst(a, ref_albedo), chroma=float(chroma))
            try:
                rec["furnace"] = (abc_white_furnace(abc_params) if name == "abc" and abc_params
                                  else float("nan") if name == "abc" else float(mm.white_furnace(brdf)))
            except (ValueError, TypeError) as e:         # a model white_furnace does not take
                rec["furnace"], rec["furnace_error"] = None, f"{type(e).__name__}: {e}"
            tables = fresnel_tables(brdf)
            rec["fresnel_tv"] = max((tv_ratio(t) for t in tables), default=None)
        except Exception as e:                           # noqa: BLE001 - recorded per fit
            rec["error"] = f"{type(e).__name__}: {e}"
        per[name] = rec
    row["fits"] = per
    row["data_albedo"] = np.round(ref_albedo, 4).tolist()
    row["data_albedo_off_normal"] = np.round(mm.directional_albedo(data, (OFF_NORMAL_DEG,))[0], 4).tolist()
    keep = {f"{k}|{i}": np.asarray(images[k][i], np.float32) for k in images for i in (0, 1)}
    out = work / "renders" / f"{m.key}.npz"
    out.parent.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    np.savez_compressed(buf, **keep)
    _atomic_write(out, buf.getvalue())
    return row


# ------------------------------------------------------------------------- workers
def _atomic_write(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".part")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)


def _write_json(path: Path, obj) -> None:
    _atomic_write(path, (json.dumps(obj, indent=1, default=_json_default) + "\n").encode())


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def _rounded(obj, digits: int = 5):
    """``obj`` with every float rounded to ``digits`` significant digits (smaller JSON)."""
    if isinstance(obj, float):
        return float(f"{obj:.{digits}g}") if np.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _rounded(v, digits) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_rounded(v, digits) for v in obj]
    return obj


def _error_text(e: BaseException) -> str:
    text = f"{type(e).__name__}: {e}".strip()
    return text.splitlines()[0][:300] if text else type(e).__name__


def task_convert(m: Material, tool: Path) -> tuple[str, str | None]:
    try:
        convert(m, tool)
        return m.key, None
    except subprocess.CalledProcessError as e:
        lines = (e.stderr or b"").decode(errors="replace").strip().splitlines()
        return m.key, (lines[-1][:300] if lines else f"exit {e.returncode}")
    except Exception as e:                               # noqa: BLE001
        return m.key, _error_text(e)


def task_baseline(m: Material, work: Path, tree: Path) -> tuple[str, str | None, float]:
    """Today's default: ``microfacet fit`` of commit 416aa6c (``tree``) in a subprocess."""
    out = work / "baseline" / f"{m.key}.npz"
    out.parent.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "PYTHONPATH": str(tree / "src")}
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "microfacet", "fit", str(m.file), "-o", str(out), "--no-picture"],
                       env=env, capture_output=True, text=True, cwd=str(tree))
    seconds = time.perf_counter() - t0
    err = work / "baseline" / f"{m.key}.error.json"
    if p.returncode != 0 or not out.with_suffix(".json").is_file():
        lines = [ln for ln in (p.stderr or p.stdout).strip().splitlines() if ln.strip()]
        msg = lines[-1][:300] if lines else f"exit {p.returncode}"
        _write_json(err, {"error": msg})
        return m.key, msg, seconds
    err.unlink(missing_ok=True)
    return m.key, None, seconds


def task_fit(m: Material, work: Path) -> tuple[str, str | None, float]:
    """:func:`microfacet.batch.tasks.fit_file` with the CLI's defaults (no picture)."""
    from microfacet.batch.tasks import fit_file
    out = work / "fits" / f"{m.key}.npz"
    out.parent.mkdir(parents=True, exist_ok=True)
    err = out.with_suffix(".error.json")
    t0 = time.perf_counter()
    try:
        fit_file(m.file, out, picture=False)
    except Exception as e:                               # noqa: BLE001 - recorded, the run goes on
        seconds = time.perf_counter() - t0
        _write_json(err, {"error": _error_text(e), "traceback": traceback.format_exc()[-2000:]})
        out.with_suffix(".json").unlink(missing_ok=True)
        return m.key, _error_text(e), seconds
    seconds = time.perf_counter() - t0
    err.unlink(missing_ok=True)
    _write_json(out.with_suffix(".wall.json"), {"seconds": seconds})
    return m.key, None, seconds


def task_evaluate(m: Material, work: Path, data: Path) -> tuple[str, str | None]:
    out = work / "results" / f"{m.key}.json"
    t0 = time.perf_counter()
    try:
        abc = abc_models(data).get(m.name) if m.group == "merl" else None
        params = read_abc(data / "anchors" / "abc_low2012_merl.csv").get(m.name) if abc is not None else None
        row = evaluate(m, work, abc, params)
    except Exception as e:                               # noqa: BLE001
        row = {"group": m.group, "name": m.name, "key": m.key, "errors": {"evaluate": _error_text(e)},
               "traceback": traceback.format_exc()[-2000:]}
    row["evaluate_seconds"] = time.perf_counter() - t0
    _write_json(out, row)
    return m.key, row["errors"].get("evaluate")


def run_pool(fn, args_list, jobs: int, what: str) -> list:
    """Run ``fn(*args)`` for each in ``args_list`` on ``jobs`` processes, printing progress."""
    results = []
    if not args_list:
        return results
    if jobs <= 1:
        for k, args in enumerate(args_list, 1):
            results.append(fn(*args))
            print(f"  {what} {k}/{len(args_list)} {results[-1][0]} {results[-1][1] or ''}", flush=True)
        return results
    ctx = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(jobs, mp_context=ctx) as pool:
        futures = [pool.submit(fn, *args) for args in args_list]
        for k, f in enumerate(concurrent.futures.as_completed(futures), 1):
            results.append(f.result())
            print(f"  {what} {k}/{len(args_list)} {results[-1][0]} {results[-1][1] or ''}", flush=True)
    return results


# -------------------------------------------------------------------------- phases
def phase_convert(materials, tool, jobs):
    todo = [(m, tool) for m in materials if m.net is not None and not m.file.is_file()]
    print(f"convert: {len(todo)} to convert into {materials[0].file.parent if materials else ''}", flush=True)
    return {k: e for k, e in run_pool(task_convert, todo, jobs, "convert") if e}


def phase_baseline(materials, work, tree, jobs, force):
    if not (tree / "src" / "microfacet").is_dir():
        print(f"baseline: no worktree at {tree} (git worktree add {tree} {BASELINE_COMMIT}); skipped", flush=True)
        return None
    todo = [(m, work, tree) for m in materials if m.file.is_file() and (force or not (
        (work / "baseline" / f"{m.key}.json").is_file() or (work / "baseline" / f"{m.key}.error.json").is_file()))]
    print(f"baseline: {len(todo)} to fit with {tree} ({BASELINE_COMMIT})", flush=True)
    t0 = time.perf_counter()
    res = run_pool(task_baseline, todo, jobs, "baseline")
    return {"n": len(todo), "wall_seconds": time.perf_counter() - t0, "failed": {k: e for k, e, _ in res if e}}


def phase_fit(materials, work, jobs, force, whole: bool = True):
    code = fit_code_mtime()
    todo = []
    for m in materials:
        js = work / "fits" / f"{m.key}.json"
        if m.file.is_file() and (force or not js.is_file() or js.stat().st_mtime < code):
            todo.append((m, work))
    print(f"fit: {len(todo)} to fit ({len(materials) - len(todo)} up to date)", flush=True)
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    res = run_pool(task_fit, todo, jobs, "fit")
    wall = time.perf_counter() - t0
    info = {"n": len(todo), "jobs": jobs, "wall_seconds": wall, "sum_seconds": sum(s for *_, s in res),
            "failed": {k: e for k, e, _ in res if e}, "date": datetime.datetime.now().isoformat(timespec="seconds"),
            "commit": _git("rev-parse", "--short", "HEAD"),
            "load_average": [round(load0, 1), round(os.getloadavg()[0], 1)]}
    if todo:
        _write_json(work / f"fit_phase_{len(todo)}.json", info)
        if whole and len(todo) == len(materials):       # the whole corpus, not an --only subset
            _write_json(work / "fit_phase_full.json", info)
    return info


def phase_evaluate(materials, work, data, jobs, force):
    deps = [Path(__file__).stat().st_mtime, (ROOT / "src" / "microfacet" / "metrics.py").stat().st_mtime]
    anchors = ROOT / "src" / "microfacet" / "anchors.py"
    if anchors.is_file():
        deps.append(anchors.stat().st_mtime)
    todo = []
    for m in materials:
        out = work / "results" / f"{m.key}.json"
        inputs = [work / "fits" / f"{m.key}.json", work / "fits" / f"{m.key}.error.json",
                  work / "baseline" / f"{m.key}.json"]
        latest = max([*deps, *(p.stat().st_mtime for p in inputs if p.is_file())])
        if force or not out.is_file() or out.stat().st_mtime < latest:
            todo.append((m, work, data))
    print(f"evaluate: {len(todo)} to evaluate", flush=True)
    run_pool(task_evaluate, todo, jobs, "evaluate")


def _git(*args) -> str:
    try:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
    except Exception:                                    # noqa: BLE001
        return ""


# -------------------------------------------------------------------------- report
def _fit(row, name):
    return (row.get("fits") or {}).get(name) or {}


def _num(v):
    return isinstance(v, (int, float)) and v is not None and np.isfinite(v)


def material_rows(rows: list[dict]) -> list[dict]:
    """The page's table: one flat record per material."""
    out = []
    for r in rows:
        best = r.get("best")
        b, t, a, z = _fit(r, best), _fit(r, "tabulated"), _fit(r, "abc"), _fit(r, "baseline")
        tvs = {k: f.get("fresnel_tv") for k, f in (r.get("fits") or {}).items()
               if k not in ("abc", "baseline") and _num(f.get("fresnel_tv"))}
        tv_fit = max(tvs, key=tvs.get) if tvs else ""
        fit_errors = {k: v for k, v in r.get("errors", {}).items() if k != "baseline"}
        per_fit_errors = {k: f["error"] for k, f in (r.get("fits") or {}).items() if "error" in f}
        out.append({
            "group": r["group"], "name": r["name"], "best": best or "",
            "log_best": b.get("log"), "log_tabulated": t.get("log"), "log_abc": a.get("log"),
            "log_baseline": z.get("log"),
            "image_best": b.get("image"), "image_tabulated": t.get("image"), "image_abc": a.get("image"),
            "image_baseline": z.get("image"),
            "grid_best": b.get("grid"), "uniform_best": b.get("uniform"),
            "albedo_best": b.get("albedo_worst"), "albedo_baseline": z.get("albedo_worst"),
            "chroma_best": b.get("chroma"), "chroma_baseline": z.get("chroma"),
            "furnace_best": b.get("furnace"),
            "furnace_max": max((f.get("furnace") for k, f in (r.get("fits") or {}).items()
                                if k not in ("abc", "baseline") and _num(f.get("furnace"))), default=None),
            "tv_ratio": tvs.get(tv_fit), "tv_fit": tv_fit, "tv_baseline": z.get("fresnel_tv"),
            "seconds": r.get("wall_seconds"), "fit_seconds": r.get("fit_seconds"), "fold_seam": r.get("fold_seam"),
            "balanced_from": r.get("balanced_from"),
            "normal_jump": normal_jump(r.get("data_albedo"), r.get("data_albedo_off_normal")),
            "error": "; ".join(f"{k}: {v}" for k, v in {**fit_errors, **per_fit_errors}.items()),
            "baseline_error": r.get("errors", {}).get("baseline", ""),
        })
    return out


def goals(table: list[dict], n_expected: int, phase: dict | None) -> dict:
    """The issue's goal figures computed from the table."""
    from microfacet.measured.merl import SEAM_LIMIT     # a table above it is not reciprocal
    merl = [r for r in table if r["group"] == "merl"]
    both = [r for r in merl if all(_num(r[k]) for k in ("log_best", "log_abc", "image_best", "image_abc"))]
    beat = [r for r in both if r["log_best"] <= r["log_abc"] and r["image_best"] <= r["image_abc"]]
    beat_log = [r for r in both if r["log_best"] <= r["log_abc"]]
    beat_img = [r for r in both if r["image_best"] <= r["image_abc"]]

    def med(rows, k):
        v = [r[k] for r in rows if _num(r[k])]
        return float(np.median(v)) if v else None

    def paired(rows):
        p = [r for r in rows if _num(r["image_best"]) and _num(r["image_baseline"])]
        return {"n": len(p), "best": med(p, "image_best"), "baseline": med(p, "image_baseline"),
                "ratio": (med(p, "image_best") / med(p, "image_baseline")) if p and med(p, "image_baseline") else None}

    def failing(key, ok):
        return [f"{r['group']}/{r['name']}" for r in table if not (_num(r[key]) and ok(r[key]))]

    g = {
        "n_materials": len(table), "n_expected": n_expected,
        "abc": {"n_merl": len(merl), "n_compared": len(both), "n_both": len(beat), "n_log": len(beat_log),
                "n_image": len(beat_img), "fraction": len(beat) / len(merl) if merl else None,
                "goal": 0.9, "losing": [r["name"] for r in both if r not in beat]},
        "image_median": {"merl": paired(merl), "all": paired(table), "goal": 0.5},
        "albedo": {"failing": failing("albedo_best", lambda v: abs(v - 1.0) <= ALBEDO_TOL), "tol": ALBEDO_TOL,
                   "floor": ALBEDO_FLOOR},
        "chroma": {"failing": failing("chroma_best", lambda v: v <= CHROMA_TOL), "tol": CHROMA_TOL,
                   "balanced": [(f"{r['group']}/{r['name']}", r["balanced_from"]["chromaticity"], r["chroma_best"])
                                for r in table if r.get("balanced_from") and _num(r["chroma_best"])]},
        "furnace": {"failing": failing("furnace_max", lambda v: v <= 1.0 + 1e-3)},
        "fresnel_tv": {"failing": [f"{r['group']}/{r['name']}" for r in table
                                   if _num(r["tv_ratio"]) and r["tv_ratio"] > TV_FACTOR * (1 + 1e-6)],
                       "n_with_tables": sum(_num(r["tv_ratio"]) for r in table),
                       "baseline_failing": sum(_num(r["tv_baseline"]) and r["tv_baseline"] > TV_FACTOR * (1 + 1e-6)
                                               for r in table)},
        "fit_failures": [f"{r['group']}/{r['name']}: {r['error']}" for r in table if r["error"] or not r["best"]],
        "baseline_failures": [f"{r['group']}/{r['name']}: {r['baseline_error']}" for r in table
                              if r["baseline_error"]],
        "fit_seconds": {"median": med(table, "seconds"), "max": max((r["seconds"] for r in table
                                                                      if _num(r["seconds"])), default=None)},
        "corpus_wall": phase,
        "fold_seam": {"ranked": [(f"{r['group']}/{r['name']}", r["fold_seam"])
                                 for r in sorted((r for r in table if _num(r.get("fold_seam"))),
                                                 key=lambda r: -r["fold_seam"])],
                      "limit": SEAM_LIMIT},
    }
    return g


def _c(v, digits=3):
    if v is None or v == "":
        return "–"
    if isinstance(v, float):
        if not np.isfinite(v):
            return "–"
        return f"{v:.{digits}f}" if abs(v) < 1000 else f"{v:.3g}"
    return str(v).replace("|", "\\|")


def format_page(table, g, meta) -> str:
    def yes(ok):
        return "**met**" if ok else "**not met**"
    a, im = g["abc"], g["image_median"]
    lines = [f"# Fit corpus: every shared corpus material fitted with the CLI's defaults", "",
             f"Generated {meta['date']} by `{meta['command']}` on {meta['machine']}, code at commit "
             f"{meta['commit']}{' (+ uncommitted changes)' if meta['dirty'] else ''}; fit file format: "
             f"{meta['format']}. Metrics: {', '.join(f'{k}: {v}' for k, v in meta['sources'].items())}. "
             f"How to run it and what the metrics mean: `docs/fit_corpus.md`.", "",
             "## Goals (issue 24)", ""]
    frac = a["fraction"]
    lines.append(f"- Best fit's log error AND image error <= ABC's (Löw et al. 2012) on "
                 f"{a['n_both']}/{a['n_merl']} MERL materials = {_c(frac, 3)} (goal >= 0.90): "
                 f"{yes(frac is not None and frac >= 0.9)}; log alone {a['n_log']}, image alone {a['n_image']}"
                 f" (of {a['n_compared']} compared).")
    for key, label in (("merl", "MERL"), ("all", "all materials")):
        p = im[key]
        lines.append(f"- Median image error, {label} ({p['n']} with both): best {_c(p['best'])} vs today's "
                     f"default (416aa6c 'ggx') {_c(p['baseline'])}, ratio {_c(p['ratio'])} (goal <= 0.5): "
                     f"{yes(p['ratio'] is not None and p['ratio'] <= 0.5)}.")
    n = g["n_materials"]

    def listed(f):
        return "" if not f else " — " + ", ".join(f[:12]) + (f" and {len(f) - 12} more" if len(f) > 12 else "")
    lines.append(f"- Directional albedo of the best fit within {ALBEDO_TOL:.0%} at 0/30/60/75° (channels with "
                 f"albedo > {ALBEDO_FLOOR}): {n - len(g['albedo']['failing'])}/{n} pass, {yes(not g['albedo']['failing'])}"
                 f"{listed(g['albedo']['failing'])}.")
    lines.append(f"- Chromaticity of the best fit's spheres within {CHROMA_TOL} of the data: "
                 f"{n - len(g['chroma']['failing'])}/{n} pass, {yes(not g['chroma']['failing'])}"
                 f"{listed(g['chroma']['failing'])}.")
    balanced = g["chroma"].get("balanced") or []
    if balanced:
        lines.append(f"- Colour balance (`microfacet.fit.colour`, under lights the image error does not use): the best "
                     f"fit of {len(balanced)}/{n} materials is balanced; its cast (the fit's own image error, 32 px, "
                     f"before → this page's, 64 px): " + ", ".join(f"{k} {_c(a)} → {_c(b)}" for k, a, b in balanced) + ".")
    lines.append(f"- White furnace <= 1 for every fit of the file: {n - len(g['furnace']['failing'])}/{n} pass, "
                 f"{yes(not g['furnace']['failing'])}{listed(g['furnace']['failing'])}.")
    tv = g["fresnel_tv"]
    lines.append(f"- Fresnel tables' total variation <= {TV_FACTOR:g}x range (every table of every fit): "
                 f"{tv['n_with_tables'] - len(tv['failing'])}/{tv['n_with_tables']} materials with tables pass, "
                 f"{yes(not tv['failing'])}{listed(tv['failing'])}; today's default fails it on "
                 f"{tv['baseline_failing']}.")
    ff = g["fit_failures"]
    lines.append(f"- Every material fits: {n - len(ff)}/{g['n_expected']} fit, {yes(not ff and n == g['n_expected'])}"
                 f"{listed(ff)}. Today's default failed on {len(g['baseline_failures'])}"
                 f"{listed(g['baseline_failures'])}.")
    w = g["corpus_wall"]
    if w:
        lines.append(f"- Corpus fit wall time with --jobs {w['jobs']}: {w['wall_seconds'] / 60:.1f} min for "
                     f"{w['n']} materials (goal: 119 in <= 15 min); per material median "
                     f"{_c(g['fit_seconds']['median'], 2)} s, max {_c(g['fit_seconds']['max'], 2)} s (fit_file wall "
                     f"in a worker, no picture; {w['date']}, commit {w['commit']}"
                     + (f"; 1-min load average {w['load_average'][0]} at the start, {w['load_average'][1]} at the end "
                        f"(a shared machine)" if w.get("load_average") else "") + ").")
    else:
        lines.append("- Corpus fit wall time: not measured in one run of every material yet.")
    ranked = g["fold_seam"]["ranked"]
    if ranked:
        rank = {k: i + 1 for i, (k, _) in enumerate(ranked)}
        seams = dict(ranked)
        failing = list(dict.fromkeys(g["albedo"]["failing"] + g["chroma"]["failing"]))
        jumps = {f"{r['group']}/{r['name']}": r.get("normal_jump") for r in table}
        lines.append(f"- Data not reciprocal (`MERLBRDF.fold_seam`: median jump of ln luminance across the "
                     f"phi_d fold > {g['fold_seam']['limit']}): {sum(v > g['fold_seam']['limit'] for _, v in ranked)}"
                     f"/{len(ranked)} tables, corpus median {_c(float(np.median([v for _, v in ranked])))}"
                     + ("; the albedo and chromaticity failures: " + ", ".join(
                         f"{k} (seam {_c(seams.get(k))}, rank {rank.get(k, '–')}"
                         + (f"; data albedo at 0° / at {OFF_NORMAL_DEG:g}°: {_c(jumps[k])}" if _num(jumps.get(k)) else "")
                         + ")" for k in failing) if failing else "")
                     + ".")
    lines += ["", "## Per material", "",
              "log / image: cosine-weighted log error and sphere-image error of the best fit, the tabulated fit, "
              "ABC (MERL) and today's default (416aa6c). albedo: the best fit's ratio fit/data farthest from 1. "
              "chroma: the best fit's chromaticity difference. furnace: the largest white furnace of the file's "
              "fits. TV/range: worst Fresnel table of the file's fits and that fit (today's default in brackets). seam: "
              "the data's jump across the phi_d fold (ln luminance). s: fit_file wall seconds.", "",
              "| group | material | best | log best | log tab | log ABC | log today | img best | img tab | img ABC "
              "| img today | albedo | chroma | furnace | TV/range | seam | s | error |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in table:
        tv = (_c(r["tv_ratio"], 2) + (f" {r['tv_fit']}" if r["tv_fit"] else "")
              + (f" ({_c(r['tv_baseline'], 1)})" if _num(r["tv_baseline"]) else ""))
        lines.append("| " + " | ".join([r["group"], r["name"], r["best"] or "–", _c(r["log_best"]),
                                        _c(r["log_tabulated"]), _c(r["log_abc"]), _c(r["log_baseline"]),
                                        _c(r["image_best"]), _c(r["image_tabulated"]), _c(r["image_abc"]),
                                        _c(r["image_baseline"]), _c(r["albedo_best"]), _c(r["chroma_best"], 4),
                                        _c(r["furnace_max"]), tv, _c(r.get("fold_seam")), _c(r["seconds"], 2),
                                        _c(r["error"] or (f"baseline: {r['baseline_error']}"
                                                          if r["baseline_error"] else ""))]) + " |")
    if meta.get("sheets"):
        lines += ["", "## Contact sheets", "",
                  "Per material: data | best | tabulated | ABC (MERL) under the directional light, then the same "
                  "under the studio environment; one exposure per material and lighting (the data's 99.5th "
                  "percentile).", ""]
        lines += [f"![{p}]({p})" for p in meta["sheets"]]
    return "\n".join(lines) + "\n"


def contact_sheets(rows: list[dict], work: Path, prefix: Path, size: int = SHEET_SIZE) -> list[Path]:
    """PNG pages of spheres, one material per row (module docstring)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from microfacet.io import to_srgb8
    from microfacet.render.lobes import LUMINANCE
    cols = ("data", "best", "tabulated", "abc")
    label_w, gap, pad = 170, 14, 2
    cell = size + pad
    pages, written = {}, []
    for r in rows:
        pages.setdefault("merl" if r["group"] == "merl" else ("rgl" if r["group"] == "rgl" else "other"), []).append(r)
    for group, grows in pages.items():
        for k in range(0, len(grows), SHEET_ROWS):
            chunk = grows[k:k + SHEET_ROWS]
            width = label_w + 2 * len(cols) * cell + gap
            height = 16 + len(chunk) * cell
            canvas = np.full((height, width, 3), 24, np.uint8)
            fig = Figure(figsize=(width / 100, height / 100), dpi=100)
            FigureCanvasAgg(fig)
            for j, light in enumerate(("directional", "environment")):
                x0 = label_w + j * (len(cols) * cell + gap)
                fig.text((x0 + len(cols) * cell / 2) / width, 1 - 6 / height, light, ha="center", va="center",
                         fontsize=6, color="0.85")
                for c, name in enumerate(cols):
                    fig.text((x0 + c * cell + cell / 2) / width, 1 - 13 / height, name, ha="center", va="center",
                             fontsize=5, color="0.7")
            for i, r in enumerate(chunk):
                y0 = 16 + i * cell
                path = work / "renders" / f"{r['key']}.npz"
                best = r.get("best")
                fig.text(4 / width, 1 - (y0 + cell / 2) / height,
                         f"{r['group']}/{r['name']}\nbest: {best or '–'}", ha="left", va="center", fontsize=5,
                         color="0.9")
                if not path.is_file():
                    continue
                imgs = np.load(path)
                for j in (0, 1):
                    ref = imgs.get(f"data|{j}")
                    lum = np.asarray(ref, float) @ LUMINANCE if ref is not None else None
                    top = float(np.percentile(lum[lum > 0], 99.5)) if lum is not None and np.any(lum > 0) else 1.0
                    exposure = float(np.log2(1.0 / top)) if np.isfinite(top) and top > 0 else 0.0
                    x0 = label_w + j * (len(cols) * cell + gap)
                    for c, name in enumerate(cols):
                        key = f"{best if name == 'best' else name}|{j}"
                        if name == "best" and not best or key not in imgs.files:
                            continue
                        img = to_srgb8(np.asarray(imgs[key], float), exposure)
                        x = x0 + c * cell
                        canvas[y0:y0 + size, x:x + size] = img[:size, :size]
            fig.figimage(canvas, 0, 0, origin="upper")
            # text last, over the image
            for t in fig.texts:
                t.set_zorder(10)
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=100, metadata={"Software": None})
            out = Path(f"{prefix}_{group}{'' if len(grows) <= SHEET_ROWS else k // SHEET_ROWS + 1}.png")
            _atomic_write(out, _quantize_png(buf.getvalue()))
            written.append(out)
    return written


def _quantize_png(png: bytes) -> bytes:
    """The PNG re-encoded as an 8-bit palette image, dithered, when Pillow is there (files
    ~3x smaller than 24-bit)."""
    try:
        from PIL import Image
    except ImportError:
        return png
    rgb = Image.open(io.BytesIO(png)).convert("RGB")
    palette = rgb.quantize(colors=256, method=Image.Quantize.MEDIANCUT)
    # Floyd-Steinberg dithering against that palette: without it, smooth shading posterizes
    # into contour rings that are not in the renders
    im = rgb.quantize(palette=palette, dither=Image.Dither.FLOYDSTEINBERG)
    out = io.BytesIO()
    im.save(out, format="PNG", optimize=True)
    return out.getvalue()


def phase_report(materials, work, out_prefix: Path, command: str, n_corpus: int, sheets: bool = True):
    rows = []
    for m in materials:
        p = work / "results" / f"{m.key}.json"
        if p.is_file():
            rows.append(json.loads(p.read_text()))
        else:
            rows.append({"group": m.group, "name": m.name, "key": m.key, "errors": {"evaluate": "not evaluated"}})
    table = material_rows(rows)
    phase = None
    full = work / "fit_phase_full.json"
    if full.is_file() and len(materials) >= n_corpus:
        phase = json.loads(full.read_text())
    g = goals(table, len(materials), phase)
    cpu = next((ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                if ln.startswith("model name")), platform.processor()) if Path("/proc/cpuinfo").is_file() else ""
    formats = {r.get("format") for r in rows if r.get("format")}
    meta = {"date": datetime.date.today().isoformat(), "command": command,
            "machine": f"{os.cpu_count()} CPUs (nproc {len(os.sched_getaffinity(0))}), {cpu}, "
                       f"Python {platform.python_version()}",
            "commit": _git("rev-parse", "--short", "HEAD"),
            "dirty": bool(_git("status", "--porcelain", "--untracked-files=no", "src")),
            "format": " + ".join(sorted(formats)) or "none", "sources": metric_sources()}
    if sheets:
        meta["sheets"] = [p.name for p in contact_sheets(rows, work, out_prefix)]
    page = format_page(table, g, meta)
    _atomic_write(out_prefix.with_suffix(".md"), page.encode())
    page_json = _rounded({"meta": meta, "goals": g, "materials": table, "raw": rows})
    _atomic_write(out_prefix.with_suffix(".json"), (json.dumps(page_json, separators=(",", ":"),
                                                                default=_json_default) + "\n").encode())
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(table[0]) if table else ["group"])
    w.writeheader()
    w.writerows(table)
    _atomic_write(out_prefix.with_suffix(".csv"), buf.getvalue().encode())
    return g


# ---------------------------------------------------------------------------- main
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--data", type=Path, default=DATA, help=f"shared data folder (default {DATA})")
    ap.add_argument("--cache", type=Path, default=CACHE, help=f"converted corpus files (default {CACHE})")
    ap.add_argument("--work", type=Path, default=WORK, help=f"fits, baseline, results, renders (default {WORK})")
    ap.add_argument("--jobs", "-j", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--only", nargs="+", metavar="NAME", help="materials: group/name, name or a shell pattern")
    ap.add_argument("--phase", nargs="+", default=["all"],
                    choices=["all", "convert", "baseline", "fit", "evaluate", "report"])
    ap.add_argument("--baseline-tree", type=Path, default=BASELINE_TREE,
                    help=f"worktree of commit {BASELINE_COMMIT} (default {BASELINE_TREE})")
    ap.add_argument("--force", action="store_true", help="redo the chosen phases even where up to date")
    ap.add_argument("--out", type=Path, default=RESULTS / "fit_corpus",
                    help="results prefix: .md, .json, .csv and _*.png (default experiments/results/fit_corpus)")
    ap.add_argument("--no-sheets", action="store_true", help="no contact sheets")
    a = ap.parse_args(argv)
    tool = a.data.parent / "tools" / "nbrdf_to_merl.py"
    if not (a.data / "nbrdf").is_dir() or not tool.is_file():
        raise SystemExit(f"--data {a.data}: needs nbrdf/ and ../tools/nbrdf_to_merl.py")
    everything = corpus(a.data, a.cache)
    materials = select(everything, a.only)
    phases = {"convert", "baseline", "fit", "evaluate", "report"} if "all" in a.phase else set(a.phase)
    command = "python experiments/fit_corpus.py " + " ".join(argv if argv is not None else sys.argv[1:])
    a.work.mkdir(parents=True, exist_ok=True)
    if phases & {"convert", "baseline", "fit", "evaluate"}:
        failed = phase_convert(materials, tool, a.jobs)
        for k, e in failed.items():
            print(f"  conversion failed: {k}: {e}", flush=True)
    if "baseline" in phases:
        info = phase_baseline(materials, a.work, a.baseline_tree, a.jobs, a.force)
        if info:
            print(f"baseline: {info['n']} in {info['wall_seconds']:.1f} s, failed: {info['failed']}", flush=True)
    if "fit" in phases:
        info = phase_fit(materials, a.work, a.jobs, a.force, whole=len(materials) == len(everything))
        print(f"fit: {info['n']} in {info['wall_seconds']:.1f} s wall (--jobs {a.jobs}), failed: {info['failed']}",
              flush=True)
    if "evaluate" in phases:
        phase_evaluate(materials, a.work, a.data, a.jobs, a.force)
    if "report" in phases:
        g = phase_report(materials, a.work, a.out, command, len(everything), sheets=not a.no_sheets)
        print(json.dumps({k: v for k, v in g.items() if k not in ("fit_failures",)}, indent=1, default=str)[:3000])
        print(f"wrote {a.out.with_suffix('.md')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
