"""The suite's order (tests/conftest.py): modules holding the slowest tests first, each module's slow
tests first, a module's tests kept together, by the seconds of tests/durations.json."""
import json
from types import SimpleNamespace

from conftest import DURATIONS, SLOW_TEST_S, known_durations, slowest_first


def _items(*ids):
    return [SimpleNamespace(nodeid=i) for i in ids]


def test_slowest_modules_and_tests_come_first_and_modules_stay_together():
    items = _items("a.py::t1", "a.py::t2", "b.py::t1", "b.py::t2", "b.py::t3", "c.py::t1", "c.py::t2")
    seconds = {"b.py::t3": 90.0, "b.py::t1": 5.0, "c.py::t2": 20.0, "a.py::t1": 0.5, "gone.py::t": 300.0}
    order = [i.nodeid for i in slowest_first(items, seconds)]
    assert order == ["b.py::t3", "b.py::t1", "b.py::t2", "c.py::t2", "c.py::t1", "a.py::t1", "a.py::t2"]


def test_without_durations_the_order_is_unchanged():
    items = _items("b.py::t1", "a.py::t1", "a.py::t2")
    assert slowest_first(items, {}) == items
    assert slowest_first(items, {"a.py::t1": SLOW_TEST_S / 2}) == items      # not slow: not moved


def test_the_durations_file_names_slow_tests_of_this_suite():
    """tests/durations.json parses, every entry is slow, and most entries name files that exist (a
    stale entry only loses its place in the order)."""
    raw = json.loads(DURATIONS.read_text())
    assert raw and known_durations() == {k: float(v) for k, v in raw.items()}
    assert all(v >= SLOW_TEST_S for v in raw.values())
    files = {k.split("::")[0] for k in raw}
    root = DURATIONS.parent.parent
    assert sum((root / f).is_file() for f in files) >= 0.8 * len(files)
