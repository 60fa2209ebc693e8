"""The demo's fitting section (:mod:`microfacet.demo`): which materials it fits (the shared
corpus, or the built-in ones with a note), what it shows (data | best | tabulated | ABC
with each one's errors) and that the figures it prints are those of the fit file it made."""
from __future__ import annotations

import re
from html import unescape

import numpy as np
import pytest
from conftest import CORPUS, NBRDF_TO_MERL, corpus_file

import microfacet.demo as demo
from microfacet.errors import MicrofacetError


# ---------------------------------------------------------------- materials
def test_without_the_corpus_the_builtin_materials_stand_in_with_a_note(tmp_path):
    examples, note = demo.fit_materials(data=tmp_path / "nowhere")
    assert [ex.key for ex in examples] == [ex.key for ex in demo.fit_examples()]
    assert all(ex.brdf is not None and ex.abc is None for ex in examples)
    assert "corpus was not found" in note and str(tmp_path / "nowhere" / "nbrdf") in note
    quick, _ = demo.fit_materials(quick=True, data=tmp_path / "nowhere")
    assert [ex.key for ex in quick] == [examples[0].key]


@pytest.mark.skipif(not (CORPUS.is_dir() and NBRDF_TO_MERL.is_file()), reason="no ../shared corpus here")
def test_with_the_corpus_the_materials_are_corpus_ones_with_their_abc_fits():
    from microfacet.anchors import read_abc
    examples, note = demo.fit_materials()
    assert [ex.corpus for ex in examples] == list(demo.CORPUS_MATERIALS)
    assert "Neural-BRDF corpus" in note
    published = read_abc(CORPUS.parent / "anchors" / "abc_low2012_merl.csv")
    for ex in examples:
        assert ex.abc is not None
        assert ex.abc.B == published[ex.key].B and np.array_equal(ex.abc.kd, published[ex.key].kd)


def test_a_missing_corpus_material_is_one_line_naming_the_file(tmp_path):
    (tmp_path / "data" / "nbrdf").mkdir(parents=True)
    with pytest.raises(MicrofacetError, match=r"nbrdf/merl/unobtainium\.npz: corpus material"):
        demo.corpus_file("merl/unobtainium", data=tmp_path / "data")


def test_corpus_file_uses_the_test_suites_cache(monkeypatch, tmp_path):
    """The demo converts into the same cache as tests/conftest.py (no second copy)."""
    monkeypatch.setenv("MICROFACET_CORPUS_CACHE", str(tmp_path / "cache"))
    assert demo.corpus_cache() == tmp_path / "cache"
    if not (CORPUS / "merl" / "nickel.npz").is_file() or not NBRDF_TO_MERL.is_file():
        pytest.skip("no ../shared corpus here")
    cached = tmp_path / "cache" / "merl__nickel.binary"
    cached.parent.mkdir()
    cached.symlink_to(corpus_file("merl/nickel"))            # already converted: not converted again
    assert demo.corpus_file("merl/nickel") == cached


def test_a_fit_example_takes_exactly_one_source():
    brdf = demo.fit_examples()[0].brdf
    with pytest.raises(ValueError, match="exactly one of brdf, path and corpus"):
        demo.FitExample("x", "x")
    with pytest.raises(ValueError, match="exactly one of brdf, path and corpus"):
        demo.FitExample("x", "x", brdf=brdf, corpus="merl/nickel")


def test_shown_fits_are_the_best_and_the_tabulated_or_the_best_analytic():
    def summary(best, images):
        return {"best": best, "fits": {k: {"model": None if k.endswith("_moments") else {"type": "x"},
                                           "metrics": {"image": v, "log": 0.01}} for k, v in images.items()}}
    images = {"tabulated": 0.3, "ggx_moments": 0.05, "lobe": 0.2, "two_lobes": 0.1}
    assert demo.shown_fits(summary("two_lobes", images)) == [("best: two_lobes", "two_lobes"),
                                                              ("tabulated fit", "tabulated")]
    images["tabulated"] = 0.01                    # the tabulated fit is the best: the best loadable analytic fit
    assert demo.shown_fits(summary("tabulated", images)) == [("best: tabulated", "tabulated"),
                                                              ("best analytic: two_lobes", "two_lobes")]


# ---------------------------------------------------------------- the section
def _section(tmp_path, example, note=""):
    result = demo.fit_and_picture(example, tmp_path / "work", 32)
    html = demo.fit_section(tmp_path, 32, [example], results=[result], note=note)
    return result, unescape(html)


def _check_section(tmp_path, example, result, html):
    from microfacet.fit import load
    from microfacet.fit.outputs import IMAGE_SIZE
    from microfacet.metrics import ImageError
    summary = result["summary"]
    fits, best = summary["fits"], summary["best"]
    # the best is the fit of least image error, and what the picture shows as the best is it
    assert fits[best]["metrics"]["image"] == min(f["metrics"]["image"] for f in fits.values())
    data = example.material()
    shown = load(result["npz"], model="best")
    assert ImageError(data, size=IMAGE_SIZE)(shown) == pytest.approx(fits[best]["metrics"]["image"], abs=2e-6)
    # the table: best, then image and log errors of best / tabulated / ABC as in the summary
    row = re.search(rf"<tr><td>{re.escape(example.label)}</td>(.*?)</tr>", html).group(1)
    cells = re.findall(r"<td>(.*?)</td>", row)
    assert cells[0] == best
    abc = result["abc"]
    images = [fits[best]["metrics"]["image"], fits["tabulated"]["metrics"]["image"]] + ([abc["image"]] if abc else [])
    assert cells[1] == " / ".join(f"{v:.3f}" for v in images) + ("" if abc else " / —")
    logs = [fits[best]["metrics"]["log"], fits["tabulated"]["metrics"]["log"]] + ([abc["log"]] if abc else [])
    assert cells[2] == " / ".join(f"{v:.4f}" for v in logs) + ("" if abc else " / —")
    # the pictures: the comparison PNG and one environment sphere (PNG + EXR) per BRDF shown
    labels = ["data", *(label for label, _ in result["shown"])] + ([demo.ABC_LABEL] if abc else [])
    assert list(result["environment"]) == labels
    assert (tmp_path / "fitting" / f"{example.key}.png").read_bytes() == result["picture"]
    srcs = [s for s in re.findall(r'<img src="([^"]+)"', html) if "-environment-" in s]
    assert len(srcs) == len(labels)
    for src, label in zip(srcs, labels):
        assert (tmp_path / src).stat().st_size > 0 and (tmp_path / src).with_suffix(".exr").is_file()
        image = result["environment"][label]
        assert np.isfinite(image).all() and image.max() > 0, label


def test_the_section_of_a_builtin_material_says_the_corpus_is_missing(tmp_path):
    example = demo.fit_examples()[0]
    _, note = demo.fit_materials(data=tmp_path / "nowhere")
    result, html = _section(tmp_path, example, note)
    assert "corpus was not found" in html and result["abc"] is None and demo.ABC_LABEL not in html
    _check_section(tmp_path, example, result, html)


def test_the_section_of_a_corpus_material_shows_its_abc_fit(tmp_path):
    """A MERL corpus material: data | best | tabulated (or best analytic) | ABC, the ABC's
    errors by the fits' judges."""
    path = corpus_file("merl/specular-orange-phenolic")
    example = next(ex for ex in demo.corpus_examples() if ex.key == "specular-orange-phenolic")
    result, html = _section(tmp_path, example)
    from microfacet.fit.outputs import IMAGE_SIZE, LOG_PAIRS
    from microfacet.measured import load
    from microfacet.metrics import ImageError, LogError
    data = load(path)
    assert result["abc"]["image"] == pytest.approx(ImageError(data, size=IMAGE_SIZE)(example.abc), rel=1e-9)
    assert result["abc"]["log"] == pytest.approx(LogError(data, n=LOG_PAIRS)(example.abc), rel=1e-9)
    _check_section(tmp_path, example, result, html)
