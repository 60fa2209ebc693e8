"""The demo's Mitsuba section (:func:`microfacet.mitsuba.demo.demo_section`) at a tiny size:
its HTML names every render with a time, the errors are finite and its images exist; the
best fit of a fit file renders in Mitsuba as the library renders it.
Skips like the other Mitsuba tests (no ``mitsuba``; ``llvm_ad_rgb`` falls back to
``scalar_rgb`` where libLLVM is missing, so the section runs either way)."""
from __future__ import annotations

import re

import pytest

mi = pytest.importorskip("mitsuba", reason="the Mitsuba plugins need the optional `mitsuba` package "
                                           "(pip install 'microfacet[mitsuba]')")
pytest.importorskip("drjit", reason="the Mitsuba plugins need drjit (installed with mitsuba)")

from microfacet.mitsuba.demo import STEPS, demo_section  # noqa: E402


def fit_file(tmp_path, example, best: bool = True):
    """A small fit file of a built-in material: its tabulated fit (resolution 16) and the
    material itself as the analytic fit ``"lobe"``, the best where ``best``."""
    import microfacet as mf
    from microfacet.fit.spec import to_spec
    fit = mf.fit.fit(example.brdf, resolution=16)
    path = tmp_path / f"{example.key}.npz"
    path.write_bytes(fit.to_bytes(fits={"lobe": to_spec(example.brdf)}, best="lobe" if best else "tabulated"))
    return path


@pytest.mark.parametrize("variant", [None, "scalar_rgb"])     # None: llvm_ad_rgb where it runs
def test_section_writes_images_and_timed_html(tmp_path, variant):
    from microfacet.demo import fit_examples
    fits = [(ex, fit_file(tmp_path, ex, best=k == 0)) for k, ex in enumerate(fit_examples())]
    steps = []
    html = demo_section(tmp_path, size=16, spp=2, reference_spp=8, variant=variant, progress=steps.append,
                        fits=fits)
    assert html.startswith('<section id="mitsuba">') and html.endswith("</section>")
    assert variant is None or f"variant {variant}" in html
    assert sum(steps) == STEPS
    sources = re.findall(r'<img src="([^"]+)"', html)
    assert len(sources) == 4 * len(fits) + 3 + 1
    for src in sources:
        png = tmp_path / src
        assert png.stat().st_size > 0 and png.with_suffix(".exr").stat().st_size > 0
    captions = re.findall(r"<small>(.*?)</small>", html)
    rendered = [c for c in captions if "spp" in c]
    assert len(rendered) == 2 * len(fits) + 3 + 1
    assert all(re.search(r"\d+\.\d\d s", c) for c in rendered)
    errors = [float(e) for c in captions for e in re.findall(r"rel\. (?:error|difference) (\d+\.\d+)", c)]
    assert len(errors) == len(fits) + 2 and all(0 <= e < 10 for e in errors)
    # the row names the fit rendered: the file's best ("lobe" in the first, "tabulated" in the second)
    assert "(lobe)</th>" in html and "(tabulated)</th>" in html
    for ex, _ in fits:                                     # the fit files travel with the section
        assert (tmp_path / "mitsuba" / f"{ex.key}.npz").is_file()


def test_best_fit_renders_as_the_library_renders_it(tmp_path):
    """mf_fitted use=best (default) under the directional light equals the library's render of
    the same fit up to the noise of Mitsuba's pixel integral: a smooth lobe (Beckmann
    alpha 0.35 copper, the file's best), 32 px at 64 spp."""
    from microfacet.demo import fit_examples
    ex = fit_examples()[1]
    html = demo_section(tmp_path, size=32, spp=64, reference_spp=8, fits=[(ex, fit_file(tmp_path, ex))])
    diff, rest = (float(x) for x in re.search(r"rel\. difference (\d+\.\d+) \((\d+\.\d+) outside", html).groups())
    assert diff < 0.03 and rest < 0.03, (diff, rest)
    from microfacet.io import read_exr
    library = read_exr(tmp_path / "mitsuba" / f"{ex.key}_library.exr")
    mitsuba = read_exr(tmp_path / "mitsuba" / f"{ex.key}_direct.exr")
    assert abs(mitsuba.sum() / library.sum() - 1) < 0.01


def test_section_without_fits_fits_the_demo_materials(tmp_path, monkeypatch):
    """Called alone, the section fits the demo's materials itself (no shared data here: the
    built-in ones, as microfacet fit does) and renders each file's best fit."""
    import microfacet.demo_materials as demo          # where the demo's materials live
    monkeypatch.setenv("MICROFACET_DATA", str(tmp_path / "no_data"))
    examples = demo.fit_examples()[:1]
    monkeypatch.setattr(demo, "fit_examples", lambda: examples)      # one material: keep the test short
    html = demo_section(tmp_path, size=16, spp=2, reference_spp=8)
    from microfacet.fit import fit_names
    best = fit_names(tmp_path / "mitsuba" / f"{examples[0].key}.npz")[1]
    assert f"{examples[0].label} ({best})" in html


def test_section_rejects_bad_sizes(tmp_path):
    with pytest.raises(ValueError, match="spp"):
        demo_section(tmp_path, spp=0)
    with pytest.raises(ValueError, match="leadr_width"):
        demo_section(tmp_path, leadr_width=4)


def test_run_demo_counts_the_section_steps():
    from microfacet.demo import MITSUBA_STEPS
    assert MITSUBA_STEPS == STEPS
