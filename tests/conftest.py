"""Test-suite options: ``@pytest.mark.slow`` marks the long validation sweeps, which run in
CI (``CI=true``) or with ``pytest --slow`` and are skipped, with that reason, elsewhere.
``DATA`` is the shared test data (``$MICROFACET_DATA``, else ``../shared/data`` beside the
repository; absent from a user's clone: tests that need it skip)."""
import os
import signal
from pathlib import Path

import numpy as np
import pytest

#: The suite tests the compiled kernels where they apply, so a BRDF compiles its kernel at its first
#: call (microfacet.kernels.COMPILE "wait"; the library's default runs NumPy while the kernel compiles
#: in the background, tested in tests/test_cold_start.py). Set before microfacet is imported.
os.environ.setdefault("MICROFACET_COMPILE", "wait")

DATA = Path(os.environ.get("MICROFACET_DATA") or Path(__file__).resolve().parents[2] / "shared" / "data")


def pytest_addoption(parser):
    parser.addoption("--slow", action="store_true", help="also run the long validation sweeps (@slow)")
    parser.addoption("--store-durations", action="store_true",
                     help=f"merge the seconds (setup + call + teardown) of the tests run into {DURATIONS.name}, "
                          "by which the suite runs its slowest tests first")


def pytest_configure(config):
    config.addinivalue_line("markers", "slow: long validation sweep; runs in CI (CI=true) or with --slow")


def run_slow(config) -> bool:
    return config.getoption("--slow") or os.environ.get("CI", "").lower() in ("true", "1")


def pytest_collection_modifyitems(config, items):
    items[:] = slowest_first(items, known_durations())
    if run_slow(config):
        return
    skip = pytest.mark.skip(reason="slow validation sweep: runs in CI (CI=true) or with --slow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


#: Seconds of the slower tests (setup + call + teardown) of a full run, by node id: the order in
#: which the suite runs them (``pytest --store-durations`` merges a run's into it).
DURATIONS = Path(__file__).with_name("durations.json")
#: Tests at least this slow (seconds, :data:`DURATIONS`) count as slow for the order.
SLOW_TEST_S = 1.0


def known_durations() -> dict:
    """:data:`DURATIONS` as ``{node id: seconds}`` (empty if absent or unreadable)."""
    import json
    try:
        return {str(k): float(v) for k, v in json.loads(DURATIONS.read_text()).items()}
    except (OSError, ValueError, AttributeError):
        return {}


def slowest_first(items, seconds: dict) -> list:
    """``items`` with the modules that hold the slowest tests first (by their slowest test, per
    ``seconds``) and, within each module, its slow tests first (slowest first), the rest in their
    order: ``pytest -n`` deals tests out in this order, so the long ones start early instead of
    ending the run on one worker while the others idle. A module's tests stay together (its
    module-scoped fixtures are set up once per worker, as in file order); without ``seconds`` the
    order is unchanged."""
    if not seconds:
        return list(items)
    by_module: dict = {}
    for i, item in enumerate(items):
        t = seconds.get(item.nodeid, 0.0)
        by_module.setdefault(item.nodeid.split("::")[0], []).append((-t if t >= SLOW_TEST_S else 0.0, i, item))
    modules = sorted(by_module.values(), key=lambda tests: (min(t for t, _, _ in tests), tests[0][1]))
    return [item for tests in modules for _, _, item in sorted(tests, key=lambda x: x[:2])]


_RUN_SECONDS: dict = {}


def pytest_runtest_logreport(report):
    """Sums each test's phases for ``--store-durations`` (under ``pytest -n`` the workers' reports
    reach the controlling process, which writes the file)."""
    _RUN_SECONDS[report.nodeid] = _RUN_SECONDS.get(report.nodeid, 0.0) + report.duration


def pytest_sessionfinish(session):
    import json
    if not session.config.getoption("--store-durations") or hasattr(session.config, "workerinput"):
        return
    merged = {**known_durations(), **{k: round(v, 2) for k, v in _RUN_SECONDS.items()}}
    slow = {k: v for k, v in sorted(merged.items(), key=lambda kv: -kv[1]) if v >= SLOW_TEST_S}
    DURATIONS.write_text(json.dumps(slow, indent=0) + "\n")


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


# -- GL (tests/test_glsl.py, tests/test_backend_drift.py) ----------------------------------
@pytest.fixture(scope="module")
def gl():
    """The GLSL harness on a real GL (moderngl, headless EGL); skips with the reason where there
    is none, fails under ``CI=true``."""
    try:
        from microfacet.glsl import harness
        harness.context()
    except Exception as e:   # ImportError, moderngl/EGL errors
        reason = f"no OpenGL 3.3 on EGL ({type(e).__name__}: {' '.join(str(e).split())[:120]})"
        if os.environ.get("CI", "").lower() in ("true", "1"):
            pytest.fail(f"{reason} [CI=true: GL tests must run; make setup installs moderngl and Mesa]")
        pytest.skip(reason)
    return harness


def rel_error(got, ref) -> float:
    """Largest relative error where ``|ref|`` exceeds 1e-3 of its maximum (at least 100 values)."""
    got, ref = np.asarray(got, float), np.asarray(ref, float)
    big = np.abs(ref) > 1e-3 * np.abs(ref).max()
    assert big.sum() >= 100, "the comparison needs non-negligible values"
    return float(np.max(np.abs(got[big] - ref[big]) / np.abs(ref[big])))
