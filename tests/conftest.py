"""Test-suite options: ``@pytest.mark.slow`` marks the long validation sweeps, which run in
CI (``CI=true``) or with ``pytest --slow`` and are skipped, with that reason, elsewhere.
``DATA`` is the shared test data (``$MICROFACET_DATA``, else ``../shared/data`` beside the
repository; absent from a user's clone: tests that need it skip)."""
import os
import signal
from pathlib import Path

import pytest

#: The suite tests the compiled kernels where they apply, so a BRDF compiles its kernel at its first
#: call (microfacet.kernels.COMPILE "wait"; the library's default runs NumPy while the kernel compiles
#: in the background, tested in tests/test_cold_start.py). Set before microfacet is imported.
os.environ.setdefault("MICROFACET_COMPILE", "wait")

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


#: The shared Neural-BRDF corpus (119 networks) and its converter to MERL-format files.
CORPUS = DATA / "nbrdf"
NBRDF_TO_MERL = DATA.parent / "tools" / "nbrdf_to_merl.py"
#: Where corpus materials are converted to (kept between runs: 35 MB each).
CORPUS_CACHE = Path(os.environ.get("MICROFACET_CORPUS_CACHE")
                    or Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "microfacet" / "corpus")
#: A handful of corpus materials for tests, not tuned on: a mirror-like metal, a glossy
#: metal, a metallic paint, a coated plastic, a fabric and an RGL paint.
CORPUS_SAMPLE = ("merl/chrome", "merl/ss440", "merl/blue-metallic-paint", "merl/specular-orange-phenolic",
                 "merl/red-fabric", "rgl/ilm_solo_m_68_rgb")


def corpus_file(name: str) -> Path:
    """The MERL-format file of corpus material ``name`` (``"merl/chrome"``, ``"rgl/..."``,
    ``"nielsen/..."``), converted by ``nbrdf_to_merl.py`` on first use into
    :data:`CORPUS_CACHE` (atomically: concurrent test workers may convert the same one)."""
    import subprocess
    import sys
    import tempfile
    net = CORPUS / f"{name}.npz"
    if not net.is_file() or not NBRDF_TO_MERL.is_file():
        pytest.skip(f"corpus material {name} needs {net} and {NBRDF_TO_MERL} (../shared absent)")
    out = CORPUS_CACHE / f"{name.replace('/', '__')}.binary"
    if not out.is_file():
        out.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=out.parent, suffix=".binary")
        os.close(fd)
        try:
            subprocess.run([sys.executable, str(NBRDF_TO_MERL), str(net), "-o", tmp], check=True,
                           capture_output=True)
            os.replace(tmp, out)
        finally:
            Path(tmp).unlink(missing_ok=True)
    return out


@pytest.fixture(scope="session")
def corpus():
    """``corpus(name) -> Path``: a corpus material as a MERL-format file (:func:`corpus_file`)."""
    return corpus_file
