"""Import cost: ``import microfacet`` and ``microfacet --help`` import neither Numba nor
SciPy nor the submodules (PEP 562 lazy attributes); the CLI's spelled-out constants
agree with the modules they stand for."""
import subprocess
import sys

import microfacet as mf


def _modules_after(code: str) -> set[str]:
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys; print(' '.join(sys.modules))"],
                         capture_output=True, text=True, check=True)
    return set(out.stdout.split())


def test_import_is_light():
    loaded = _modules_after("import microfacet")
    assert not loaded & {"numba", "scipy", "numpy", "microfacet.fit", "microfacet.brdf"}


def test_help_imports_no_numerics():
    loaded = _modules_after("from microfacet.cli import main\nimport contextlib, io\n"
                            "with contextlib.redirect_stdout(io.StringIO()): main(['--help'])")
    assert not loaded & {"numba", "scipy", "microfacet.demo", "microfacet.brdf", "microfacet.fit"}


def test_lazy_names_resolve():
    assert mf.GGX is mf.distributions.GGX and mf.MicrofacetBRDF is mf.brdf.MicrofacetBRDF
    assert mf.fit.fit_analytic is not None and mf.metrics.fit_error is not None
    assert set(mf.__all__) <= set(dir(mf))
    try:
        mf.no_such_name
    except AttributeError as e:
        assert "no_such_name" in str(e)
    else:
        raise AssertionError("mf.no_such_name did not raise")


def test_cli_constants_match_modules():
    from microfacet.cli import demo as cli_demo, fit as cli_fit
    from microfacet import demo
    from microfacet.fit import analytic, outputs
    assert (cli_demo.DEFAULT_SIZE, cli_demo.DEFAULT_SPP, cli_demo.DEFAULT_SEED) == \
        (demo.DEFAULT_SIZE, demo.DEFAULT_SPP, demo.DEFAULT_SEED)
    assert cli_fit.GAFS == mf.brdf.GAFS
    assert set(cli_fit.FRESNELS) == set(analytic.FRESNELS)
    assert tuple(m.replace("-", "_") for m in cli_fit.METHODS) == outputs.METHODS
    assert cli_fit.DIFFUSE == outputs.DIFFUSE
    assert cli_fit.ALBEDO_WEIGHT == analytic.ALBEDO_WEIGHT
