"""What keeps ``microfacet demo`` fast: BRDFs sent to its pool workers reuse the cached
kernels (their kernel record is made again, read-only, not unpickled writeable), inline
tasks run once however often their result is asked for, and the section times it logs."""
from __future__ import annotations

import logging
import pickle

import numpy as np

import microfacet as mf
from microfacet import demo
from microfacet.brdf import MicrofacetBRDF


def test_pickled_brdf_makes_its_kernel_record_again_read_only():
    """Numba compiles one version per read-only flag: an unpickled record with writeable
    arrays made every pool worker compile the kernels again (not in Numba's cache)."""
    for fresnel in (mf.fresnel.Conductor.metal("Au"), mf.fresnel.Tabulated([0.0, 0.5, 1.0], [[0.1] * 3] * 3)):
        brdf = MicrofacetBRDF(mf.GGX(alpha=0.2), fresnel=fresnel)
        assert brdf.params is not None                      # made before pickling, as the demo's lobes do
        copy = pickle.loads(pickle.dumps(brdf))
        f = copy.params.fresnel
        assert not any(a.flags.writeable for a in (f.fp, f.tx, f.tv))
        wi = wo = np.array([[0.0, 0.0, 1.0]])
        np.testing.assert_array_equal(copy.eval(wi, wo), brdf.eval(wi, wo))


def test_inline_task_runs_once():
    calls = []
    task = demo._Inline().submit(lambda x: calls.append(x) or len(calls), 7)
    assert task.result() == 1 and task.result() == 1 and calls == [7]


def test_demo_logs_each_section_time(tmp_path, caplog):
    fig = demo.thesis_figures()[0]
    small = demo.DemoFigure(fig.key, fig.title, fig.caption, ((("", fig.panels[:1])),))
    with caplog.at_level(logging.INFO, logger="microfacet.demo"):
        demo.run_demo(tmp_path / "out", size=8, spp=1, figures=[small], fits=[], leadr=False, glints=False,
                      viewer=False, mitsuba=False, exports=False)
    lines = [r.getMessage() for r in caplog.records if r.name == "microfacet.demo"]
    assert any(line.startswith("demo: figures 2.2-2.6") and " s (ended at " in line for line in lines), lines
    assert lines[-1].startswith("demo: all sections: ")
