"""Python API hardening and parameter sweeps through every public BRDF model.

* The BRDF protocol (``eval``, ``eval_cos``, ``pdf``, ``sample``) of every BRDF-like object
  rejects directions that are not unit length (``microfacet.brdf.UNIT_TOLERANCE``), NaN,
  infinite or zero, and uniforms outside ``[0, 1]``, with a ``ValueError`` naming the
  argument; ``Lambertian`` reflectance must lie in ``[0, 1]``.
* Sweeps (Hypothesis, seeded): Beckmann / GGX with every GAF, alpha 1e-4..2, |rho| <= 0.999,
  mean slopes to +-3, views to 89.99 degrees, float32 and float64 directions; Lambertian;
  a tabulated fit: results finite and >= 0, ``weight = eval_cos / pdf``, albedo <= 1 (mean
  sampling weight), and the documented ``ValueError`` for invalid parameters.
  ``MICROFACET_SWEEP_EXAMPLES`` sets the number of examples (default 60); the
  ``slow``-marked grid covers every corner of the parameter box.
"""
from __future__ import annotations

import itertools
import os
import warnings

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis", reason="the sweeps need the `hypothesis` test extra")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

import microfacet as mf  # noqa: E402
from microfacet import kernels  # noqa: E402
from microfacet.brdf import UNIT_TOLERANCE  # noqa: E402
from microfacet.geometry import spherical_to_cartesian, unit_deviation  # noqa: E402

SWEEP = settings(max_examples=int(os.environ.get("MICROFACET_SWEEP_EXAMPLES", "60")), deadline=None,
                 derandomize=True, database=None, suppress_health_check=list(HealthCheck))
N_FURNACE = 4000
# MC bound on the mean sampling weight: weights lie in [0, 1] (G2 / G1 <= 1, F <= 1), so
# the standard error is <= 0.5 / sqrt(N); 5 sigma.
FURNACE_SLACK = 5 * 0.5 / np.sqrt(N_FURNACE)


def _upper(rng, n):
    w = rng.normal(size=(n, 3))
    w[:, 2] = np.abs(w[:, 2])
    return w / np.linalg.norm(w, axis=-1, keepdims=True)


# ---------------------------------------------------------------------- BRDF zoo
@pytest.fixture(scope="module")
def zoo(tmp_path_factory):
    """One of every BRDF-like object: analytic, Lambertian, measured (MERL, UTIA, RGL),
    a tabulated fit and a glint patch BRDF."""
    from microfacet.glints import Microsurface
    from microfacet.glints.figures import scratched_normal_map
    from microfacet.measured import MERLBRDF, UTIABRDF, merl
    from microfacet.measured.tensor_file import write_tensor_file
    rng = np.random.default_rng(0)
    folder = tmp_path_factory.mktemp("zoo")
    tab = lambda *shape: rng.uniform(0.5, 1.5, shape).astype(np.float32)  # noqa: E731
    rgl = folder / "z.bsdf"
    rgl.write_bytes(write_tensor_file({
        "version": np.array([1, 0], np.uint32), "description": np.frombuffer(b"z", np.uint8),
        "phi_i": np.zeros(1, np.float32), "theta_i": np.linspace(0, 1.2, 3).astype(np.float32),
        "sigma": tab(2, 8), "ndf": tab(2, 8), "vndf": tab(1, 3, 4, 4), "luminance": tab(1, 3, 4, 4),
        "rgb": tab(1, 3, 3, 4, 4), "jacobian": np.array([1], np.uint8), "valid": np.ones(2, np.uint8)}))
    ms = Microsurface.from_normal_map(scratched_normal_map(8, scratches=2, seed=1), sigma_eps=0.1)
    return {
        "beckmann": mf.MicrofacetBRDF(mf.Beckmann(alpha=0.3)),
        "ggx-vgroove": mf.MicrofacetBRDF(mf.GGX(alpha_x=0.2, alpha_y=0.4, rho=0.3), gaf="vgroove"),
        "lambertian": mf.Lambertian(0.5),
        "merl": MERLBRDF(np.full(merl.SHAPE + (3,), 0.1), np.ones(merl.SHAPE, bool)),
        "utia": UTIABRDF(np.full((6, 48, 6, 48, 3), 0.1)),
        "rgl": mf.measured.load(rgl),
        "fit": mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.4)), resolution=8),
        "glints": ms.pbrdf((0.5, 0.5), np.eye(2) * 0.01),
    }


ZOO = ("beckmann", "ggx-vgroove", "lambertian", "merl", "utia", "rgl", "fit", "glints")
UP = np.array([0.0, 0.0, 1.0])
BAD_DIRS = {"not unit": [0.0, 0.0, 1.01], "doubled": [0.0, 1.2, 1.6], "NaN": [0.0, np.nan, 1.0],
            "inf": [0.0, 0.0, np.inf], "zero": [0.0, 0.0, 0.0], "size 2": [0.0, 1.0]}


@pytest.mark.parametrize("name", ZOO)
def test_protocol_rejects_bad_directions(zoo, name):
    brdf = zoo[name]
    good = np.stack([UP, mf.geometry.normalize([0.3, 0.1, 0.9])])
    for what, bad in BAD_DIRS.items():
        batch = good.copy() if what != "size 2" else np.zeros((2, 2))
        if what != "size 2":
            batch[1] = bad
        for method in (brdf.eval, brdf.eval_cos, brdf.pdf):
            with pytest.raises(ValueError, match="^wi "):
                method(batch, good)
            with pytest.raises(ValueError, match="^wo "):
                method(good, batch)
        with pytest.raises(ValueError, match="^wo "):
            brdf.sample(np.full((2, 2), 0.5), batch)


@pytest.mark.parametrize("name", ZOO)
def test_sample_rejects_uniforms_outside_unit_square(zoo, name):
    brdf = zoo[name]
    for u in ([1.5, 0.2], [0.2, -0.1], [np.nan, 0.5], [0.5]):
        with pytest.raises(ValueError, match="^u "):
            brdf.sample(np.array(u), UP)
    wi, w, p = brdf.sample(np.array([[0.0, 0.0], [1.0, 1.0], [0.5, 0.5]]), UP)   # both ends are accepted
    assert np.all(np.isfinite(wi)) and np.all(np.isfinite(w)) and np.all(np.isfinite(p))


def test_unit_tolerance_boundary_and_float32():
    brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.3))
    w = mf.geometry.normalize([0.3, -0.2, 0.8])
    for scale2, ok in ((1 + 0.9 * UNIT_TOLERANCE, True), (1 - 0.9 * UNIT_TOLERANCE, True),
                       (1 + 1.1 * UNIT_TOLERANCE, False), (1 - 1.1 * UNIT_TOLERANCE, False)):
        wi = w * np.sqrt(scale2)
        if ok:
            assert np.all(np.isfinite(brdf.eval(wi, UP)))
        else:
            with pytest.raises(ValueError, match="unit vectors"):
                brdf.eval(wi, UP)
    rng = np.random.default_rng(3)
    wi32, wo32 = _upper(rng, 1000).astype(np.float32), _upper(rng, 1000).astype(np.float32)
    np.testing.assert_allclose(brdf.eval(wi32, wo32), brdf.eval(wi32.astype(np.float64), wo32.astype(np.float64)))


def test_lambertian_reflectance_range():
    for bad in (1.5, -0.1, np.nan, [0.5, 1.2, 0.3], np.inf, "red"):
        with pytest.raises(ValueError, match="reflectance"):
            mf.Lambertian(bad)
    assert np.all(mf.Lambertian([0.0, 1.0, 0.5]).reflectance == [0.0, 1.0, 0.5])


def test_unit_deviation_kernel_matches_numpy():
    rng = np.random.default_rng(4)
    w = _upper(rng, 10001) * (1 + rng.uniform(-1e-3, 1e-3, (10001, 1)))
    assert kernels.unit_deviation(w) == pytest.approx(unit_deviation(w), rel=1e-12)
    assert kernels.unit_deviation(w[::2]) == unit_deviation(w[::2])            # non-contiguous: NumPy
    for bad in (np.nan, np.inf, -np.inf):
        v = w.copy()
        v[5000, 1] = bad
        assert kernels.unit_deviation(v) == unit_deviation(v) == np.inf
    assert kernels.unit_deviation(np.zeros((0, 3))) == unit_deviation(np.zeros((0, 3))) == 0.0


# ------------------------------------------------------------------------- sweeps
def check_brdf(brdf, theta_o: float, dtype, seed: int, n: int = N_FURNACE) -> float:
    """Finite, non-negative results at ``n`` light directions for a view at ``theta_o``
    (and at the view itself), ``weight == eval_cos / pdf``; returns the mean sampling
    weight (the albedo estimate)."""
    rng = np.random.default_rng(seed)
    wo = spherical_to_cartesian(theta_o, 0.7).astype(dtype)
    wi = _upper(rng, n).astype(dtype)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        f, fc, p = brdf.eval(wi, wo), brdf.eval_cos(wi, wo), brdf.pdf(wi, wo)
        si, w, sp = brdf.sample(rng.random((n, 2)), wo)
        back = brdf.eval(wo, wo)
    for name, a in (("eval", f), ("eval_cos", fc), ("pdf", p), ("sample wi", si), ("weight", w),
                    ("sample pdf", sp), ("backscatter", back)):
        assert np.all(np.isfinite(a)), f"{name} not finite"
    assert np.all(f >= 0) and np.all(fc >= 0) and np.all(p >= 0) and np.all(w >= 0) and np.all(sp >= 0)
    ok = sp > 0
    ref = brdf.eval_cos(si[ok], wo) / sp[ok, None]
    # 1e-6: rounding of the sampled normal is amplified up to ~2e-7 at the corners (|rho| = 0.999,
    # alpha 1e-4 vs 2, slopes of P sampled for V-groove and normal-map GAFs)
    np.testing.assert_allclose(w[ok], ref, rtol=1e-6, atol=1e-12)
    assert np.all(w[~ok] == 0)
    return float(np.mean(w, axis=0).max())


DISTS = {"beckmann": mf.Beckmann, "ggx": mf.GGX}
params = st.fixed_dictionaries({
    "dist": st.sampled_from(sorted(DISTS)), "gaf": st.sampled_from(mf.brdf.GAFS),
    "shadowing": st.booleans(),
    "log_ax": st.floats(-4, np.log10(2)), "log_ay": st.floats(-4, np.log10(2)),
    "rho": st.floats(-0.999, 0.999), "xn": st.floats(-3, 3), "yn": st.floats(-3, 3),
    "theta_o": st.floats(0, np.radians(89.99)), "dtype": st.sampled_from([np.float32, np.float64]),
})


def _microfacet(p):
    # V-grooves (Table 2.IV) are grooves about the macro normal: with a mean slope their
    # albedo exceeds 1 (up to 1.78 at alpha 0.3, mean slope (0.5, -1), grazing views), a
    # limitation of the model documented in docs/models.md, so they are swept unsheared.
    mean = (0.0, 0.0) if p["gaf"] == "vgroove" else (p["xn"], p["yn"])
    d = DISTS[p["dist"]](alpha_x=10 ** p["log_ax"], alpha_y=10 ** p["log_ay"], rho=p["rho"], mean_slope=mean)
    return mf.MicrofacetBRDF(d, fresnel=mf.fresnel.Schlick(0.9), gaf=p["gaf"], shadowing=p["shadowing"])


@SWEEP
@given(params, st.integers(0, 2**16))
def test_sweep_microfacet(p, seed):
    albedo = check_brdf(_microfacet(p), p["theta_o"], p["dtype"], seed)
    assert albedo <= 1 + FURNACE_SLACK, f"albedo {albedo}"


@pytest.mark.slow
@pytest.mark.parametrize("dist", sorted(DISTS))
@pytest.mark.parametrize("gaf", mf.brdf.GAFS)
def test_sweep_microfacet_corners(dist, gaf):
    """Every corner of the parameter box, both dtypes."""
    for ax, ay, rho, xn, yn, theta, dtype in itertools.product(
            (1e-4, 2.0), (1e-4, 2.0), (-0.999, 0.999), (-3.0, 3.0), (-3.0, 0.0), (0.0, np.radians(89.99)),
            (np.float32, np.float64)):
        p = dict(dist=dist, gaf=gaf, shadowing=True, log_ax=np.log10(ax), log_ay=np.log10(ay), rho=rho,
                 xn=xn, yn=yn)
        assert check_brdf(_microfacet(p), theta, dtype, seed=1, n=1000) <= 1 + 5 * 0.5 / np.sqrt(1000)


@pytest.mark.parametrize("theta_o", [0.0, 45.0, 80.0, 89.99])
@pytest.mark.parametrize("name", ["lambertian", "fit", "merl", "utia", "rgl"])
def test_sweep_other_models(zoo, name, theta_o):
    albedo = check_brdf(zoo[name], np.radians(theta_o), np.float64, seed=int(theta_o))
    if name in ("lambertian", "fit"):
        assert albedo <= 1 + FURNACE_SLACK


@pytest.mark.parametrize("D", [mf.Beckmann, mf.GGX], ids=lambda D: D.__name__)
def test_invalid_parameters_raise_documented_errors(D):
    for kw, name in ((dict(alpha=0.0), "alpha"), (dict(alpha=-1.0), "alpha"), (dict(alpha=np.nan), "alpha"),
                     (dict(alpha=np.inf), "alpha"), (dict(alpha=0.3, rho=1.0), "rho"),
                     (dict(alpha=0.3, rho=np.nan), "rho"), (dict(alpha=0.3, mean_slope=(np.nan, 0)), "mean"),
                     (dict(alpha=0.3, mean_slope=(np.inf, 0)), "mean")):
        with pytest.raises(ValueError, match=name):
            D(**kw)
