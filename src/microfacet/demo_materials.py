"""The demo's materials, light and preview exposure, shared by the demo (:mod:`microfacet.demo`)
and its Mitsuba section (:mod:`microfacet.mitsuba.demo`), which import them from here (so
that neither imports the other): the fitting section's materials (:func:`fit_materials`:
corpus materials of the shared Neural-BRDF corpus where it is present, else built-in
analytic ones), their fit as ``microfacet fit`` makes it (:func:`fit_demo_material`), the
directional light of the demo's spheres (:data:`LIGHT`) and the exposure of a preview
(:func:`preview_exposure`).

>>> LIGHT
DirectionalLight(direction=(-0.5, 0.5, 1.0), irradiance=1.0)
>>> CORPUS_MATERIALS[0]
'merl/nickel'
>>> examples, note = fit_materials(quick=True)
>>> len(examples)
1
>>> summary, npz = fit_demo_material(examples[0], ".")     # doctest: +SKIP
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._colour import LUMINANCE
from . import fresnel as fr
from .brdf import BRDF, MicrofacetBRDF
from .distributions import GGX, Beckmann
from .errors import MicrofacetError
from .render import DirectionalLight

__all__ = ["FitExample", "fit_examples", "fit_materials", "fit_demo_material", "corpus_examples", "corpus_file",
           "corpus_cache", "shared_data", "preview_exposure", "CORPUS_MATERIALS", "LIGHT"]

#: Directional light: 35 deg up-left of the view direction, unit irradiance.
LIGHT = DirectionalLight(direction=(-0.5, 0.5, 1.0), irradiance=1.0)

#: Corpus materials of the fitting section (names in the shared Neural-BRDF corpus,
#: ``../shared/data/nbrdf``): a glossy metal, a mirror-like metal, a coated plastic and a
#: metallic paint.
CORPUS_MATERIALS = ("merl/nickel", "merl/chrome", "merl/specular-orange-phenolic", "merl/blue-metallic-paint")


@dataclass(frozen=True)
class FitExample:
    """A material of the fitting section, given by exactly one of: ``brdf`` (a built-in
    analytic BRDF, its parameters in ``label``), ``path`` (a measured file, any format of
    :func:`microfacet.measured.load`) or ``corpus`` (a name of the shared Neural-BRDF
    corpus, e.g. ``"merl/nickel"``, converted on first use by :func:`corpus_file`);
    ``abc``: its published ABC fit (:func:`microfacet.anchors.read_abc`) where there is one.

    Parameters
    ----------
    key : str
        File-name key of the material (``KEY.npz``, ``KEY.png``).
    label : str
        Its label in the pictures and tables.
    brdf : BRDF, optional
        A built-in analytic BRDF.
    path : Path, optional
        A measured file.
    corpus : str
        A name of the shared Neural-BRDF corpus (``""``: none).
    abc : BRDF, optional
        The published ABC fit (Löw et al. 2012) of a MERL material.

    Raises
    ------
    ValueError
        Where not exactly one of ``brdf``, ``path`` and ``corpus`` is given.

    Examples
    --------
    >>> from microfacet import GGX, MicrofacetBRDF
    >>> ex = FitExample("ggx", "GGX α = 0.3", MicrofacetBRDF(GGX(alpha=0.3)))
    >>> ex.material() is ex.brdf
    True
    >>> FitExample("nickel", "merl/nickel", corpus="merl/nickel").material()   # doctest: +SKIP
    >>> FitExample("none", "nothing")
    Traceback (most recent call last):
    ...
    ValueError: FitExample 'none': give exactly one of brdf, path and corpus
    """

    key: str
    label: str
    brdf: BRDF | None = None
    path: Path | None = None
    corpus: str = ""
    abc: BRDF | None = None

    def __post_init__(self):
        given = sum(x is not None and x != "" for x in (self.brdf, self.path, self.corpus))
        if given != 1:
            raise ValueError(f"FitExample {self.key!r}: give exactly one of brdf, path and corpus")

    def material(self) -> BRDF:
        """The material itself: ``brdf``, or the measured file read by
        :func:`microfacet.measured.load` (a corpus name converted first).

        Returns
        -------
        BRDF
            The analytic BRDF, or the measured one.
        """
        if self.brdf is not None:
            return self.brdf
        from .measured import load
        return load(self.path if self.path is not None else corpus_file(self.corpus))


def fit_examples() -> list[FitExample]:
    """The built-in materials, fitted where the shared corpus is absent: a GGX and a
    Beckmann conductor, analytic materials with known parameters.

    Returns
    -------
    list of FitExample
        The two materials, each with its ``brdf``.

    Examples
    --------
    >>> [ex.key for ex in fit_examples()]
    ['ggx_gold', 'beckmann_copper']
    """
    return [FitExample("ggx_gold", "GGX α = 0.2, gold",
                       MicrofacetBRDF(GGX(alpha=0.2), fresnel=fr.Conductor.metal("Au"))),
            FitExample("beckmann_copper", "Beckmann α = 0.35, copper",
                       MicrofacetBRDF(Beckmann(alpha=0.35), fresnel=fr.Conductor.metal("Cu")))]


def shared_data() -> Path:
    """The shared data folder: ``$MICROFACET_DATA``, else ``../shared/data`` beside the
    repository (where ``tests/conftest.py`` finds it); absent from a user's clone.

    Returns
    -------
    Path
        The folder (it may not exist).

    Examples
    --------
    >>> isinstance(shared_data(), Path)
    True
    """
    return Path(os.environ.get("MICROFACET_DATA") or Path(__file__).resolve().parents[2].parent / "shared" / "data")


def corpus_cache() -> Path:
    """Where corpus materials are converted to (35 MB each, kept between runs):
    ``$MICROFACET_CORPUS_CACHE``, else ``$XDG_CACHE_HOME/microfacet/corpus``, else
    ``~/.cache/microfacet/corpus`` (the test suite's cache).

    Returns
    -------
    Path
        The folder (created on the first conversion).

    Examples
    --------
    >>> isinstance(corpus_cache(), Path)
    True
    """
    return Path(os.environ.get("MICROFACET_CORPUS_CACHE")
                or Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "microfacet" / "corpus")


def _converter(data: Path) -> Path:
    return data.parent / "tools" / "nbrdf_to_merl.py"


def corpus_file(name: str, data: str | os.PathLike | None = None) -> Path:
    """The MERL-format file of corpus material ``name`` (``"merl/nickel"``, ``"rgl/..."``),
    converted from its network ``DATA/nbrdf/NAME.npz`` by ``DATA/../tools/nbrdf_to_merl.py``
    (~1.5 s) on first use into :func:`corpus_cache`, atomically (concurrent demos and tests
    may convert the same one).

    Parameters
    ----------
    name : str
        Corpus name, ``GROUP/MATERIAL``.
    data : path-like, optional
        The shared data folder; default :func:`shared_data`.

    Returns
    -------
    Path
        The cached MERL-format file.

    Raises
    ------
    MicrofacetError
        Naming the missing network or converter, or the failed conversion.

    Examples
    --------
    >>> corpus_file("merl/nickel")                  # doctest: +SKIP
    >>> corpus_file("merl/nickel", data="no-data")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    microfacet.errors.MicrofacetError: no-data/nbrdf/merl/nickel.npz: corpus material 'merl/nickel' not found ...
    """
    import subprocess
    import sys
    import tempfile
    data = shared_data() if data is None else Path(data)
    net, tool = data / "nbrdf" / f"{name}.npz", _converter(data)
    for path, what in ((net, f"corpus material {name!r}"), (tool, "the corpus converter")):
        if not path.is_file():
            raise MicrofacetError(f"{path}: {what} not found (set MICROFACET_DATA to the shared data folder)")
    out = corpus_cache() / f"{name.replace('/', '__')}.binary"
    if out.is_file():
        return out
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=out.parent, prefix=".", suffix=".binary.tmp")
    os.close(fd)
    try:
        run = subprocess.run([sys.executable, str(tool), str(net), "-o", tmp], capture_output=True, text=True,
                             timeout=600)
        if run.returncode != 0:
            why = (run.stderr.strip().splitlines() or [f"exit status {run.returncode}"])[-1]
            raise MicrofacetError(f"{net}: conversion by {tool.name} failed: {why}")
        os.replace(tmp, out)
    finally:
        Path(tmp).unlink(missing_ok=True)
    return out


def corpus_examples(names: Sequence[str] = CORPUS_MATERIALS,
                    data: str | os.PathLike | None = None) -> list[FitExample] | None:
    """The corpus materials ``names`` as :class:`FitExample` (MERL ones with their ABC fit
    from ``DATA/anchors/abc_low2012_merl.csv`` where listed), or ``None`` where the shared
    data (networks and converter) are absent. Nothing is converted yet.

    Parameters
    ----------
    names : sequence of str
        Corpus names; default :data:`CORPUS_MATERIALS`.
    data : path-like, optional
        The shared data folder; default :func:`shared_data`.

    Returns
    -------
    list of FitExample or None
        One per name, or ``None`` without the shared data.

    Examples
    --------
    >>> corpus_examples(data="no-data") is None
    True
    >>> [ex.key for ex in corpus_examples()]        # doctest: +SKIP
    ['nickel', 'chrome', 'specular-orange-phenolic', 'blue-metallic-paint']
    """
    data = shared_data() if data is None else Path(data)
    if not (data / "nbrdf").is_dir() or not _converter(data).is_file():
        return None
    abc_csv = data / "anchors" / "abc_low2012_merl.csv"
    from .anchors import read_abc
    abc = read_abc(abc_csv) if abc_csv.is_file() else {}
    out = []
    for name in names:
        group, _, material = name.partition("/")
        out.append(FitExample(material, name, corpus=name, abc=abc.get(material) if group == "merl" else None))
    return out


def fit_materials(quick: bool = False, data: str | os.PathLike | None = None) -> tuple[list[FitExample], str]:
    """The fitting section's materials and a sentence saying what they are: the corpus
    materials :data:`CORPUS_MATERIALS` where the shared data are (:func:`corpus_examples`),
    else the built-in :func:`fit_examples`, the sentence saying that the corpus was not
    found.

    Parameters
    ----------
    quick : bool
        The first material only (small demos, tests).
    data : path-like, optional
        The shared data folder; default :func:`shared_data`.

    Returns
    -------
    examples : list of FitExample
        The materials.
    note : str
        What they are (where the corpus was looked for where it is absent).

    Examples
    --------
    >>> examples, note = fit_materials(data="no-data")
    >>> [ex.key for ex in examples]
    ['ggx_gold', 'beckmann_copper']
    >>> note.startswith("The shared corpus was not found")
    True
    """
    data = shared_data() if data is None else Path(data)
    corpus = corpus_examples(data=data)
    if corpus is None:
        examples = fit_examples()
        note = (f"The shared corpus was not found (looked for {data / 'nbrdf'} and {_converter(data)}; set "
                "MICROFACET_DATA to the shared data folder): the demo's built-in analytic materials stand in "
                "for measured ones, without published fits.")
    else:
        examples = corpus
        note = (f"Materials of the shared Neural-BRDF corpus ({data / 'nbrdf'}), each converted to a MERL-format "
                f"file by {_converter(data).name} (cached in {corpus_cache()}).")
    return (examples[:1] if quick else examples), note


def fit_demo_material(example: FitExample, work: str | os.PathLike) -> tuple[dict, Path]:
    """Fit ``example`` as ``microfacet fit`` does (:func:`microfacet.fit.outputs.fit_material`,
    the CLI's defaults, no picture) into ``work/KEY.npz`` (with ``KEY.json``).

    Parameters
    ----------
    example : FitExample
        The material.
    work : path-like
        The folder of the fit files.

    Returns
    -------
    summary : dict
        ``OUT.json``'s dict (the fits, their metrics, the best).
    npz : Path
        The fit file.

    Examples
    --------
    >>> example = fit_examples()[0]
    >>> example.key
    'ggx_gold'
    >>> summary, npz = fit_demo_material(example, ".")   # doctest: +SKIP
    >>> npz.name                                         # doctest: +SKIP
    'ggx_gold.npz'
    """
    from .fit.outputs import fit_material
    npz = Path(work) / f"{example.key}.npz"
    return fit_material(example.material(), npz, picture=False), npz


def preview_exposure(image: np.ndarray) -> float:
    """Stops putting the 99.5th-percentile luminance of ``image`` at 1 (0 for a black image).

    Parameters
    ----------
    image : ndarray
        Linear RGB image ``(..., 3)``.

    Returns
    -------
    float
        Exposure in stops (:func:`microfacet.io.write_png`'s ``exposure``).

    Examples
    --------
    >>> preview_exposure(np.full((4, 4, 3), 0.25))
    2.0
    >>> preview_exposure(np.zeros((4, 4, 3)))
    0.0
    """
    lum = image @ LUMINANCE
    lit = lum[lum > 0]
    top = float(np.percentile(lit, 99.5)) if lit.size else 0.0
    return float(np.log2(1.0 / top)) if np.isfinite(top) and top > 0 else 0.0
