"""Chi-square test for the tests (see :mod:`microfacet.validation`)."""
from microfacet.validation import chi2_test  # noqa: F401
