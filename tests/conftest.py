"""Test-suite options: ``@pytest.mark.slow`` marks the long validation sweeps, which run in
CI (``CI=true``) or with ``pytest --slow`` and are skipped, with that reason, elsewhere.
``DATA`` is the shared test data (``$MICROFACET_DATA``, else ``../shared/data`` beside the
repository; absent from a user's clone: tests that need it skip)."""
import os
import signal
from pathlib import Path

import pytest

DATA = Path(os.environ.get("MICROFACET_DATA") or Path(__file__).resolve().parents[2] / "shared" / "data")


def pytest_addoption(parser):
    parser.addoption("--slow", action="store_true", help="also run the long validation sweeps (@slow)")


def pytest_configure(config):
    config.addinivalue_line("markers", "slow: long validation sweep; runs in CI (CI=true) or with --slow")


def run_slow(config) -> bool:
    return config.getoption("--slow") or os.environ.get("CI", "").lower() in ("true", "1")


def pytest_collection_modifyitems(config, items):
    if run_slow(config):
        return
    skip = pytest.mark.skip(reason="slow validation sweep: runs in CI (CI=true) or with --slow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


def default_sigint() -> None:
    """``preexec_fn`` for a child process that a test stops with Ctrl-C (SIGINT): a shell
    starts background jobs with SIGINT ignored and children inherit that, so such a child
    would never see the signal."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
