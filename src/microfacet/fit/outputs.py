"""What ``microfacet fit`` writes: a fit's files and the summary table of a folder of fits.

For a material fitted by :func:`microfacet.fit.fit` (power iterations, thesis Ch. 4):

* ``NAME.npz`` — the tabulated fit (``fit.save``), loadable by :func:`microfacet.fit.load`;
* ``NAME.json`` — ``{"beckmann": {"alpha_x", "alpha_y", "rho"}, "ggx": {...},
  "fresnel": {...}, "seconds": ..., "errors": {...}, ...}``: the analytic fits
  (``fit.to_beckmann()``, ``fit.to_ggx()``), the fitted Fresnel term, the fitting time
  and the fit errors of :func:`microfacet.metrics.fit_error`;
* ``NAME.png`` — the comparison picture of :func:`microfacet.render.save_fit_comparison`
  (data, tabulated fit, GGX, Beckmann).

A folder of materials gives one such triple per material and ``summary.csv`` /
``summary.md`` (one row per input file). Every file is written atomically.
"""
from __future__ import annotations

import csv
import io
import json
import os
import time
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from ..errors import MicrofacetError
from ..io import write_text
from ..metrics import describe_fit_error, fit_error

__all__ = ["material_name", "material_files", "fit_material", "fit_folder", "distribution_params",
           "fresnel_json", "summary_row", "format_summary_markdown", "format_summary_csv",
           "SUMMARY_COLUMNS"]

#: File suffixes dropped from a material's name (longest first).
_SUFFIXES = (".binary.gz", ".bsdf.gz", ".bin.gz", ".binary", ".bsdf", ".bin", ".gz")
#: Columns of ``summary.csv`` (``summary.md`` shows the same, formatted).
SUMMARY_COLUMNS = ("material", "file", "format", "status", "seconds",
                   "error_tabulated", "error_ggx", "error_beckmann",
                   "ggx_alpha_x", "ggx_alpha_y", "ggx_rho",
                   "beckmann_alpha_x", "beckmann_alpha_y", "beckmann_rho")


def material_name(path: str | os.PathLike) -> str:
    """File name without its measured-BRDF suffix: ``nickel.binary.gz`` -> ``nickel``."""
    name = Path(path).name
    for suffix in _SUFFIXES:
        if name.lower().endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)]
    return name


def material_files(folder: str | os.PathLike) -> list[Path]:
    """Regular, non-hidden files directly in ``folder``, sorted by name (formats are
    recognised by content when they are loaded)."""
    folder = Path(folder)
    return sorted(p for p in folder.iterdir() if p.is_file() and not p.name.startswith("."))


def distribution_params(brdf) -> dict[str, float]:
    """``{"alpha_x", "alpha_y", "rho"}`` of a :class:`microfacet.MicrofacetBRDF`."""
    d = brdf.distribution
    rho = float(d.rho)
    return {"alpha_x": float(d.alpha_x), "alpha_y": float(d.alpha_y),
            "rho": 0.0 if abs(rho) < 1e-12 else rho}      # isotropic fits: rounding noise


def fresnel_json(fresnel) -> dict:
    """A JSON-able description of a Fresnel term: its type and parameters or samples."""
    kind = type(fresnel).__name__.lower()
    if hasattr(fresnel, "cos_theta_d") and hasattr(fresnel, "values"):
        return {"type": kind, "cos_theta_d": np.asarray(fresnel.cos_theta_d, float).round(6).tolist(),
                "rgb": np.asarray(fresnel.values, float).round(6).tolist()}
    params = {k: np.asarray(v).tolist() for k, v in vars(fresnel).items()
              if not k.startswith("_") and isinstance(v, (int, float, np.ndarray, tuple, list))}
    return {"type": kind, **params}


def _fit_fresnel(fit):
    """The fitted Fresnel term: ``fit.fresnel``, else the GGX fit's."""
    f = getattr(fit, "fresnel", None)
    return f if f is not None else fit.to_ggx().fresnel


def _run_fit(brdf, resolution: int, anisotropic: bool, gaf: str):
    from .fitted import fit
    return fit(brdf, resolution=resolution, anisotropic=anisotropic, gaf=gaf)


def fit_material(brdf, out_npz: str | os.PathLike, resolution: int = 90, anisotropic: bool = False,
                 gaf: str = "smith", title: str = "") -> dict:
    """Fit ``brdf`` and write ``out_npz`` with its ``.json`` and ``.png`` beside it
    (its folder is created if needed).

    Returns the JSON summary (module docstring). ``seconds`` is the time of the fit
    alone (not of the error evaluation, picture or files).
    """
    out_npz = Path(out_npz)
    if out_npz.is_dir():
        raise MicrofacetError(f"{out_npz}: is a folder")
    out_npz.parent.mkdir(parents=True, exist_ok=True)     # before the work, not after
    t0 = time.perf_counter()
    fit = _run_fit(brdf, resolution, anisotropic, gaf)
    seconds = time.perf_counter() - t0
    ggx, beckmann = fit.to_ggx(), fit.to_beckmann()
    fits = {"tabulated": fit, "ggx": ggx, "beckmann": beckmann}
    errors = fit_error(brdf, fits)
    summary = {
        "beckmann": distribution_params(beckmann),
        "ggx": distribution_params(ggx),
        "fresnel": fresnel_json(_fit_fresnel(fit)),
        "seconds": round(seconds, 4),
        "errors": {"tabulated": errors["tabulated"], "ggx": errors["ggx"], "beckmann": errors["beckmann"],
                   "n_pairs": errors["n_pairs"], "metric": describe_fit_error()},
        "resolution": int(resolution), "anisotropic": bool(anisotropic), "gaf": gaf,
    }
    fit.save(out_npz)                               # atomic (FittedBRDF.save)
    write_text(out_npz.with_suffix(".json"), json.dumps(summary, indent=2) + "\n")
    from ..render import save_fit_comparison
    save_fit_comparison(out_npz.with_suffix(".png"),
                        {"data": brdf, "tabulated fit": fit, "GGX": ggx, "Beckmann": beckmann},
                        title=title or material_name(out_npz), planes_deg=(0, 90) if anisotropic else (0,))
    return summary


def summary_row(name: str, path, fmt: str, summary: dict | None, status: str = "ok") -> dict:
    """A row of the folder summary (:data:`SUMMARY_COLUMNS`) from a JSON summary."""
    row = dict.fromkeys(SUMMARY_COLUMNS, "")
    row.update(material=name, file=Path(path).name, format=fmt, status=status)
    if summary is not None:
        row["seconds"] = summary["seconds"]
        for kind in ("tabulated", "ggx", "beckmann"):
            row[f"error_{kind}"] = summary["errors"][kind]
        for kind in ("ggx", "beckmann"):
            for key, value in summary[kind].items():
                row[f"{kind}_{key}"] = value
    return row


def format_summary_csv(rows: Sequence[dict]) -> str:
    """The rows as CSV (header :data:`SUMMARY_COLUMNS`, full precision)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=SUMMARY_COLUMNS, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def _cell(value, digits: int = 4) -> str:
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value).replace("|", "\\|")


def format_summary_markdown(rows: Sequence[dict]) -> str:
    """The rows as a Markdown table, plus a note on the error metric."""
    head = ("material", "format", "fit s", "err tab", "err GGX", "err Beck",
            "GGX αx", "GGX αy", "GGX ρ", "Beck αx", "Beck αy", "Beck ρ", "status")
    keys = ("material", "format", "seconds", "error_tabulated", "error_ggx", "error_beckmann",
            "ggx_alpha_x", "ggx_alpha_y", "ggx_rho", "beckmann_alpha_x", "beckmann_alpha_y",
            "beckmann_rho", "status")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(_cell(r[k], 3 if k == "seconds" else 4) if not k.endswith("_rho") or r[k] == ""
                                else f"{r[k]:+.4f}" for k in keys) + " |" for r in rows]
    return "\n".join(lines) + f"\n\nErrors: {describe_fit_error()}.\n"


def fit_folder(folder: str | os.PathLike, out_dir: str | os.PathLike, resolution: int = 90,
               anisotropic: bool = False, gaf: str = "smith",
               progress: Callable[[Sequence[Path]], object] | None = None) -> list[dict]:
    """Fit every material file of ``folder`` into ``out_dir`` and write the summaries.

    A file that cannot be read or fitted is reported by a warning and a summary row with
    its error as status; the others are still fitted. ``progress`` wraps the list of
    files (e.g. ``tqdm``). Returns the summary rows; raises :class:`MicrofacetError` when
    the folder holds no file.
    """
    from ..measured import load
    folder, out = Path(folder), Path(out_dir)
    files = material_files(folder)
    if not files:
        raise MicrofacetError(f"{folder}: no files to fit")
    if out.exists() and not out.is_dir():
        raise MicrofacetError(f"{out}: exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    rows, used = [], set()
    for path in (progress(files) if progress else files):
        name = material_name(path)
        name = path.name if name in used else name          # nickel.binary and nickel.binary.gz
        used.add(name)
        try:
            brdf = load(path)
            summary = fit_material(brdf, out / f"{name}.npz", resolution, anisotropic, gaf, title=name)
            rows.append(summary_row(name, path, getattr(brdf, "format", ""), summary))
        except (MicrofacetError, ValueError, OSError) as e:
            reason = " ".join(str(e).split()) or type(e).__name__
            reason = reason.removeprefix(f"{path}: ")        # the file is named already
            warnings.warn(f"{path.name}: not fitted: {reason}", RuntimeWarning, stacklevel=2)
            rows.append(summary_row(name, path, "", None, status=f"error: {reason}"))
    write_text(out / "summary.csv", format_summary_csv(rows))
    write_text(out / "summary.md", format_summary_markdown(rows))
    return rows
