"""The validation tools can fail: they catch wrong samplers and wrong normalizations."""
import numpy as np
import pytest

import microfacet as mf
from microfacet.cli import main
from microfacet.validation import chi2_test, integrate_hemisphere


class _SkewedPdf(mf.MicrofacetBRDF):
    """A BRDF whose pdf claims ~10 % more density near the pole than its sampler produces."""

    def pdf(self, wi, wo):
        p = super().pdf(wi, wo)
        return p * (1.0 + 0.1 * np.asarray(wi)[..., 2]) / 1.08


def test_chi2_rejects_a_wrong_pdf_and_accepts_the_right_one():
    wo = mf.geometry.spherical_to_cartesian(0.5, 0.2)
    good = mf.MicrofacetBRDF(mf.GGX(alpha=0.4))
    bad = _SkewedPdf(mf.GGX(alpha=0.4))
    assert chi2_test(good, wo, n=200_000)[0] > 1e-3
    assert chi2_test(bad, wo, n=200_000)[0] < 1e-6


def test_quadrature_sees_a_misnormalized_ndf():
    d = mf.Beckmann(alpha_x=0.05, alpha_y=0.3, rho=0.8, mean_slope=(0.5, 0.5))
    total = integrate_hemisphere(lambda h: d.ndf(h) * h[..., 2] * (1 + 1e-6 * h[..., 0]), d)
    assert abs(total - 1) > 1e-8           # a 1e-6 perturbation is visible above the 1e-14 noise
    assert abs(integrate_hemisphere(lambda h: d.ndf(h) * h[..., 2], d) - 1) < 1e-12


@pytest.mark.slow
def test_validate_command(tmp_path, capsys):
    out = tmp_path / "report.md"
    assert main(["validate", "--quick", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "| check |" in text and "NO" not in text and out.read_text() == text
