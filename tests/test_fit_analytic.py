"""mf.fit.fit_analytic (least-squares analytic fits) and SumBRDF (mixture sampling)."""
import itertools
import os
from pathlib import Path

import numpy as np
import pytest

import microfacet as mf
from microfacet.fit.analytic import SumBRDF, fit_analytic
from microfacet.metrics import directional_albedo, fit_error

GOLD = mf.fresnel.Conductor.metal("Au")
#: The shared data: $MICROFACET_DATA, else ../shared/data beside the repository.
DATA = Path(os.environ.get("MICROFACET_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "data"))
SHARED = sorted(DATA.glob("merl/*.binary*")) + sorted(DATA.glob("rgl/*.bsdf"))
FAST = dict(n=14, n_uniform=2**10)


def lobe(brdf):
    return brdf.brdfs[0] if isinstance(brdf, SumBRDF) else brdf


@pytest.mark.parametrize("family, model", [(mf.GGX, "ggx"), (mf.Beckmann, "beckmann")])
@pytest.mark.parametrize("alpha", [0.05, 0.3, 0.8])
def test_same_family_round_trip_recovers_alpha(family, model, alpha):
    truth = mf.MicrofacetBRDF(family(alpha=alpha), fresnel=mf.fresnel.Schlick((0.9, 0.6, 0.3)))
    start = mf.MicrofacetBRDF(family(alpha=0.5 * alpha))                 # a wrong start
    f = fit_analytic(truth, model, fresnel="schlick", start=start, **FAST)
    assert float(f.distribution.alpha_x) == pytest.approx(alpha, rel=1e-3)
    np.testing.assert_allclose(f.fresnel.f0, (0.9, 0.6, 0.3), atol=2e-3)
    assert fit_error(truth, f, n=12)["fit"] < 1e-3


def test_anisotropic_round_trip_with_correlation():
    truth = mf.MicrofacetBRDF(mf.GGX(alpha_x=0.15, alpha_y=0.3, rho=0.25), fresnel=GOLD)
    f = fit_analytic(truth, "ggx", anisotropic=True, fresnel="conductor", start=truth, **FAST)
    d = f.distribution
    assert (float(d.alpha_x), float(d.alpha_y), float(d.rho)) == pytest.approx((0.15, 0.3, 0.25), rel=1e-2)
    np.testing.assert_allclose(f.fresnel(np.linspace(0, 1, 11)), GOLD(np.linspace(0, 1, 11)), atol=5e-3)


def test_diffuse_base_is_recovered_and_returned_as_a_sum():
    kd = np.array([0.5, 0.3, 0.2])
    truth = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.2), fresnel=mf.fresnel.Schlick(0.04)), mf.Lambertian(kd))
    f = fit_analytic(truth, "ggx", diffuse=True, fresnel="schlick", start=lobe(truth), **FAST)
    assert isinstance(f, SumBRDF) and isinstance(f.brdfs[1], mf.Lambertian)
    np.testing.assert_allclose(f.brdfs[1].reflectance, kd, rtol=1e-2)
    assert float(lobe(f).distribution.alpha_x) == pytest.approx(0.2, rel=1e-2)
    without = fit_analytic(truth, "ggx", diffuse=False, fresnel="schlick", start=lobe(truth), **FAST)
    assert isinstance(without, mf.MicrofacetBRDF)
    assert fit_error(truth, f, n=12)["fit"] < 0.1 * fit_error(truth, without, n=12)["fit"]


@pytest.mark.parametrize("fresnel", ["schlick", "table", "conductor"])
def test_fresnel_stays_in_unit_interval_on_too_bright_data(fresnel):
    class Bright(mf.BRDF):                     # 3x a white mirror lobe: F would have to be 3
        inner = mf.MicrofacetBRDF(mf.GGX(alpha=0.3))

        def eval_cos(self, wi, wo):
            return 3.0 * self.inner.eval_cos(wi, wo)
    f = fit_analytic(Bright(), "ggx", fresnel=fresnel, start=Bright.inner, **FAST)
    values = f.fresnel(np.linspace(0.0, 1.0, 101))
    assert np.all(values >= 0.0) and np.all(values <= 1.0 + 1e-12) and np.all(np.isfinite(values))


def test_cross_family_least_squares_beats_the_moment_conversion():
    """The demo's Beckmann copper fitted as GGX: half the error of the moment conversion."""
    truth = mf.MicrofacetBRDF(mf.Beckmann(alpha=0.35), fresnel=mf.fresnel.Conductor.metal("Cu"))
    tab = mf.fit.fit(truth, resolution=32)
    e = fit_error(truth, {"moments": tab.to_ggx(), "ls": fit_analytic(truth, "ggx", start=tab, **FAST)}, n=16)
    assert e["ls"] < 0.5 * e["moments"]


def test_moment_conversion_solves_its_own_fresnel_table():
    """``to_ggx()`` solves a Fresnel table for the converted NDF instead of keeping the
    one solved for the tabulated NDF: on Beckmann copper the GGX conversion's error
    drops from 1.53 to 0.40; within the family the table comes back (GGX Schlick, 3e-3);
    against the data (``reference``) it does not depend on the albedo tuning of the fit's
    own table (a fit of a copper lobe over a base, without a base of its own)."""
    truth = mf.MicrofacetBRDF(mf.Beckmann(alpha=0.35), fresnel=mf.fresnel.Conductor.metal("Cu"))
    tab = mf.fit.fit(truth, resolution=32)
    e = fit_error(truth, {"own": tab.to_ggx(), "kept": tab.to_ggx(resolve_fresnel=False)}, n=16)
    assert e["own"] < 0.3 * e["kept"]
    ggx = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Schlick((0.9, 0.6, 0.3)))
    c = np.linspace(0.05, 1.0, 20)
    np.testing.assert_allclose(mf.fit.fit(ggx, resolution=32).to_ggx().fresnel(c), ggx.fresnel(c), atol=5e-3)
    mixed = SumBRDF(truth, mf.Lambertian(0.1))
    tables = [mf.fit.fit(mixed, resolution=32, albedo_weight=w) for w in (0.0, 4.0)]
    assert not np.allclose(tables[0].fresnel.values, tables[1].fresnel.values, atol=1e-3)
    own = [t.to_beckmann(reference=mixed).fresnel.values for t in tables]
    np.testing.assert_allclose(own[0], own[1], atol=1e-9)
    with pytest.raises(ValueError, match="options of method='moments'"):
        tab.to_ggx(method="least_squares", reference=truth)


def test_coat_round_trip_recovers_both_lobes():
    """A rough lobe (constant F, table) under a sharp coat (f0 0.04, f90 0.3), reflecting
    less than it receives: ``coat=True`` recovers both roughnesses and the sharp lobe's
    Fresnel term; one lobe (+ diffuse) cannot fit it. (Two Schlick lobes, both of
    grazing value 1, would reflect ~2 at grazing views: the energy constraint forbids
    fitting them.)"""
    from microfacet.fit.analytic import TABLE_NODES, coat_fresnel
    rgb = np.array([0.6, 0.4, 0.2])
    truth = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Tabulated(
                        TABLE_NODES, np.repeat(rgb[None], len(TABLE_NODES), 0))),
                    mf.MicrofacetBRDF(mf.GGX(alpha=0.04), fresnel=coat_fresnel(0.04, 0.3)))
    assert max_albedo(truth) < 0.99
    start = mf.MicrofacetBRDF(mf.GGX(alpha=0.3))
    f = fit_analytic(truth, "ggx", fresnel="table", coat=True, coat_fresnel="schlick", start=start, **FAST)
    sharp, rough = sorted(f.brdfs, key=lambda b: float(b.distribution.alpha_x))
    assert abs(rough.distribution.alpha_x / 0.3 - 1.0) < 0.01 and abs(sharp.distribution.alpha_x / 0.04 - 1.0) < 0.01
    assert np.allclose(sharp.fresnel(np.array([1.0, 0.0])), [[0.04] * 3, [0.3] * 3], atol=0.01)
    one = fit_analytic(truth, "ggx", diffuse=True, fresnel="table", start=start, **FAST)
    e = fit_error(truth, {"coat": f, "one": one}, n=16)
    assert e["coat"] < 0.01 < e["one"]


def test_table_coat_recovers_a_second_metallic_lobe():
    """A coat with a 7-node Fresnel table (the default ``coat_fresnel``) fits a second
    lobe whose Fresnel term falls towards grazing (as gold-metallic-paint's, which Schlick's
    ``f0, f90`` cannot follow): both roughnesses within 1 % and the sharp lobe's table
    within 0.01, the grid error at the optimizer's tolerance. (A Schlick coat fits it as
    well here, by taking the rough lobe's constant Fresnel term: both fits' errors are
    ~1e-8 to 1e-7, no test of which is the better.)"""
    from microfacet.fit.analytic import TABLE_NODES
    falling = np.interp(TABLE_NODES, [0.0, 0.5, 1.0], [0.0, 0.15, 0.25])[:, None] * [1.0, 0.7, 0.3]
    truth = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.35), fresnel=mf.fresnel.Tabulated(
                        TABLE_NODES, np.repeat([[0.3, 0.2, 0.05]], len(TABLE_NODES), 0))),
                    mf.MicrofacetBRDF(mf.GGX(alpha=0.08), fresnel=mf.fresnel.Tabulated(TABLE_NODES, falling)))
    start = mf.MicrofacetBRDF(mf.GGX(alpha=0.3))
    fit = fit_analytic(truth, "ggx", coat=True, start=start, **FAST)
    rough, sharp = fit.brdfs                    # the same Fresnel model: the coat is the sharper lobe
    assert abs(rough.distribution.alpha_x / 0.35 - 1.0) < 0.01 and abs(sharp.distribution.alpha_x / 0.08 - 1.0) < 0.01
    np.testing.assert_allclose(sharp.fresnel(TABLE_NODES), falling, atol=0.01)
    assert fit_error(truth, fit, n=16)["fit"] < 1e-6
    with pytest.raises(ValueError, match="coat_fresnel must be one of"):
        fit_analytic(truth, "ggx", coat=True, coat_fresnel="conductor", **FAST)


def test_fitted_brdf_converts_by_least_squares_without_data():
    """``to_ggx/to_beckmann(method="least_squares")`` fit the tabulated fit itself: the same
    family comes back, and the cross family beats the moment conversion on the fit."""
    truth = mf.MicrofacetBRDF(mf.Beckmann(alpha=0.3), fresnel=mf.fresnel.Schlick(0.5))
    tab = mf.fit.fit(truth, resolution=32)
    same = tab.to_beckmann(method="least_squares", **FAST)
    assert isinstance(same, mf.MicrofacetBRDF) and abs(same.distribution.alpha_x / 0.3 - 1.0) < 0.01
    e = fit_error(tab, {"moments": tab.to_ggx(), "ls": tab.to_ggx(method="least_squares", **FAST)}, n=16)
    assert e["ls"] < 0.5 * e["moments"]
    with pytest.raises(ValueError, match="method must be one of"):
        tab.to_ggx(method="fast")


def test_analytic_fits_do_not_import_the_tabulated_fit():
    """No import circle: ``fit.fitted`` imports ``fit.analytic``, never the reverse."""
    import ast
    import microfacet.fit.analytic as analytic
    tree = ast.parse(Path(analytic.__file__).read_text())
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert "fitted" not in imported and not any(m and m.endswith(".fitted") for m in imported)


def test_bad_arguments_raise_clear_errors():
    truth = mf.MicrofacetBRDF(mf.GGX(alpha=0.2))
    with pytest.raises(ValueError, match="model must be one of"):
        fit_analytic(truth, "phong", start=truth)
    with pytest.raises(ValueError, match="fresnel must be one of"):
        fit_analytic(truth, "ggx", fresnel="cook", start=truth)
    with pytest.raises(ValueError, match="start must be"):
        fit_analytic(truth, "ggx", start=mf.Lambertian(0.5), **FAST)


def test_sum_brdf_sampling_is_unbiased_and_consistent():
    s = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.15), fresnel=GOLD), mf.Lambertian((0.2, 0.4, 0.6)),
                weights=(0.7, 0.3))
    wo = np.array([np.sin(0.6), 0.0, np.cos(0.6)])
    u = np.random.default_rng(4).random((200_000, 2))
    wi, weight, pdf = s.sample(u, wo)
    ok = pdf > 0
    np.testing.assert_allclose(pdf[ok], s.pdf(wi[ok], wo), rtol=1e-9)
    np.testing.assert_allclose(weight[ok], s.eval_cos(wi[ok], wo) / pdf[ok, None], rtol=1e-9)
    mc = weight.mean(axis=0)
    np.testing.assert_allclose(mc, directional_albedo(s, (np.degrees(0.6),))[0], rtol=1e-2)
    with pytest.raises(ValueError, match="weights"):
        SumBRDF(mf.Lambertian(0.5), weights=(-1.0,))


@pytest.mark.parametrize("fresnel, diffuse, coat", [("table", True, False), ("schlick", False, False),
                                                    ("conductor", True, False), ("table", True, "table"),
                                                    ("table", True, "schlick"), ("conductor", False, "table")])
def test_node_space_objective_equals_the_direct_sum(fresnel, diffuse, coat):
    """The objective accumulated in Fresnel-node space equals the weighted sums computed
    directly from the fitted BRDF on the same pairs and albedo nodes (exact for the table,
    within the piecewise-linear Fresnel approximation otherwise)."""
    from microfacet.fit import analytic
    from microfacet.metrics import ALBEDO_VIEWS_DEG
    truth = SumBRDF(mf.MicrofacetBRDF(mf.Beckmann(alpha=0.25), fresnel=GOLD), mf.Lambertian((0.1, 0.2, 0.3)))
    data = analytic._Data(truth, 10, 2**9, (24, 12))
    problem = analytic._Problem(data, "ggx", diffuse, False, fresnel, gaf="smith", shadowing=True,
                                mean_slope=np.zeros(2), albedo_weight=2.0, coat=bool(coat),
                                coat_fresnel=coat or "table")
    q = np.log([0.2, 0.05] if coat else [0.2])
    e = problem.error(q)
    fitted = problem.brdf(q)
    f = fitted.eval_cos(data.wi, data.wo)
    ref = truth.eval_cos(data.wi[:data.m], data.wo[:data.m])
    pairs = np.sum(data.w[:, None] * (f[:data.m] - ref) ** 2)
    view = data.view
    albedo = np.stack([np.bincount(view, data.w_albedo * f[data.m:, c], minlength=len(ALBEDO_VIEWS_DEG))
                       for c in range(3)], axis=-1)
    direct = pairs + 4.0 * np.mean((albedo / data.albedo - 1.0) ** 2)
    assert e == pytest.approx(direct, rel=(1e-6 if coat else 1e-9) if fresnel == "table" else 2e-3)


def test_albedo_term_trades_shape_for_energy():
    """Two lobes fitted by one: the albedo term brings the albedo ratios towards 1, at the
    cost of a larger pair error; weight 0 is the shape-only fit."""
    from microfacet.metrics import albedo_ratios
    truth = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.08), fresnel=mf.fresnel.Schlick(0.5)),
                    mf.MicrofacetBRDF(mf.GGX(alpha=0.6), fresnel=mf.fresnel.Schlick(0.3)))
    start = mf.MicrofacetBRDF(mf.GGX(alpha=0.1))
    fits = {w: fit_analytic(truth, "ggx", start=start, albedo_weight=w, **FAST) for w in (0.0, 10.0)}
    worst = {w: np.max(np.abs(albedo_ratios(truth, f) - 1.0)) for w, f in fits.items()}
    grid = fit_error(truth, fits, n=12)
    assert worst[10.0] < 0.5 * worst[0.0]
    assert grid[0.0] < grid[10.0]
    with pytest.raises(ValueError, match="albedo_weight"):
        fit_analytic(truth, "ggx", start=start, albedo_weight=-1.0, **FAST)


def test_fits_of_one_material_share_its_data():
    from microfacet.fit import analytic
    truth = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), fresnel=GOLD)
    analytic._DATA_CACHE.pop(truth, None)
    fit_analytic(truth, "ggx", start=truth, **FAST)
    fit_analytic(truth, "beckmann", diffuse=True, start=truth, **FAST)
    assert len(analytic._DATA_CACHE[truth]) == 1


def test_golden_section_with_a_lower_bound_takes_the_same_steps():
    """A lower bound only spares evaluations: the same minimizer and value, bitwise."""
    from microfacet.fit.extract import golden_section
    calls = []

    def f(x):
        calls.append(x)
        return (x - 0.3) ** 2 + 0.1 * abs(np.sin(7.0 * x))

    def lower(x):                      # equal to f in places (an inactive constraint)
        return (x - 0.3) ** 2 + (0.0 if x < 0.25 else 0.05 * abs(np.sin(7.0 * x)))
    plain = golden_section(f, -1.0, 2.0, xatol=1e-3)
    n_plain = len(calls)
    calls.clear()
    assert golden_section(f, -1.0, 2.0, xatol=1e-3, lower=lower) == plain
    assert len(calls) < n_plain


@pytest.mark.parametrize("coat", [False, True])
def test_kept_lobes_and_sums_give_the_objective_of_a_fresh_problem(coat):
    """A problem that keeps each lobe's ``s`` and energy rows, the coat-only sums and the
    quadratic forms returns, along a path that moves one lobe at a time and comes back,
    bitwise the objective and coefficients of a fresh problem at each point (data
    brighter than a white furnace: the energy constraint is active)."""
    from microfacet.fit import analytic
    truth = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.2), fresnel=mf.fresnel.Schlick(0.3)),
                    mf.Lambertian([0.95, 0.9, 0.6]))
    data = analytic._Data(truth, 10, 2**9, (24, 12))

    def problem():
        return analytic._Problem(data, "ggx", True, False, "table", gaf="smith", shadowing=True,
                                 mean_slope=np.zeros(2), albedo_weight=4.0, coat=coat)
    kept = problem()
    path = [[0.2, 0.05], [0.25, 0.05], [0.25, 0.04], [0.2, 0.05]] if coat else [[0.2], [0.25], [0.2]]
    for q in np.log(path):
        e, c = kept.solve(q)
        e_fresh, c_fresh = problem().solve(q)
        assert e == e_fresh and np.array_equal(c, c_fresh)
    assert len(kept._lobe_rows) == (4 if coat else 2)              # built once per lobe


def test_least_coat_candidates_are_those_of_a_full_sort():
    """The coat scan's best starts (``_least``, by lower bounds) are those of sorting every
    candidate by its error, in the same order, with fewer energy rows built."""
    from microfacet.fit import analytic
    truth = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=GOLD),
                    mf.MicrofacetBRDF(mf.GGX(alpha=0.05), fresnel=mf.fresnel.Schlick(0.04)),
                    mf.Lambertian([0.1, 0.1, 0.1]))
    data = analytic._Data(truth, 12, 2**9, (24, 12))

    def problem():
        return analytic._Problem(data, "ggx", True, False, "table", gaf="smith", shadowing=True,
                                 mean_slope=np.zeros(2), albedo_weight=4.0, coat=True)
    scan = [np.append(np.log(0.3), lc) for lc in np.log(analytic._SCAN)]
    pruned, full = problem(), problem()
    order, _ = analytic._least(pruned, scan, analytic.COAT_STARTS)
    expected = sorted(range(len(scan)), key=lambda i: full.error(scan[i]))[:analytic.COAT_STARTS]
    assert list(order) == expected
    assert len(pruned._lobe_rows) < len(full._lobe_rows)


def test_coat_search_finds_the_minimum_of_every_start_refined_on_the_full_objective(monkeypatch):
    """Issue 10 (time): the coat search leads its starts to their basins on the box-only
    objective and refines only the best on ``E``; on data brighter than a white furnace (the
    energy constraint active at the optimum) it reaches the least ``E`` of refining every
    start on ``E`` (within 1e-4) and builds fewer energy rows."""
    from microfacet.fit import analytic
    truth = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Schlick(0.3)),
                    mf.MicrofacetBRDF(mf.GGX(alpha=0.05), fresnel=mf.fresnel.Schlick(0.04)),
                    mf.Lambertian([0.95, 0.9, 0.6]))
    data = analytic._Data(truth, 12, 2**9, (24, 12))
    rows = []
    albedo_rows = analytic.albedo_rows
    monkeypatch.setattr(analytic, "albedo_rows", lambda *a, **k: rows.append(1) or albedo_rows(*a, **k))

    def problem():
        return analytic._Problem(data, "ggx", True, False, "table", gaf="smith", shadowing=True,
                                 mean_slope=np.zeros(2), albedo_weight=4.0, coat=True)
    scan = [np.append(np.log(0.3), lc) for lc in np.log(analytic._SCAN)]
    searched, every = problem(), problem()
    q = analytic._coat_search(searched, scan, 200)
    e, n_searched = searched.error(q), len(rows)
    e_every = min(every.error(analytic._minimize(every, scan[i], 200))
                  for i in analytic._least(every, scan, analytic.COAT_STARTS)[0])
    assert searched.lower_bound(q) < e                                  # the constraint is active
    # 1e-4, not rounding: where a table would ring, its smoothing penalty switches on
    # (TABLE_TV_LIMIT), which makes E piecewise and the two searches' optima differ slightly
    assert e <= e_every * (1.0 + 1e-4)
    assert n_searched < len(rows) - n_searched


def test_roughness_search_skips_candidates_by_their_lower_bound():
    """Data brighter than a white furnace (the energy constraint active): the search
    that evaluates candidates by their box-only lower bound chooses the same roughness,
    to the bit, as evaluating every candidate and the golden section without it, and builds
    fewer energy rows."""
    from microfacet.fit import analytic
    from microfacet.fit.extract import golden_section
    truth = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Schlick(0.3)),
                    mf.Lambertian([0.95, 0.9, 0.6]))
    data = analytic._Data(truth, 14, 2**10, (64, 32))

    def problem():
        p = analytic._Problem(data, "ggx", True, False, "table", gaf="smith", shadowing=True,
                              mean_slope=np.zeros(2), albedo_weight=4.0)
        p.rows_built = 0
        energy_rows = p.energy_rows

        def counted(q):
            p.rows_built += 1
            return energy_rows(q)
        p.energy_rows = counted
        return p
    candidates = np.log(analytic._SCAN)
    lo, hi = np.log(analytic.ALPHA_BOUNDS)
    pruned = problem()
    chosen = analytic._minimize_log_alpha(pruned, candidates, lo, hi)
    full = problem()
    errors = [full.error(la) for la in candidates]
    assert all(full.lower_bound(la) <= e for la, e in zip(candidates, errors, strict=True))
    b = int(np.argmin(errors))
    x, fx = golden_section(full.error, candidates[b - 1], candidates[b + 1], xatol=2e-3)
    assert chosen == (float(x) if fx <= errors[b] else float(candidates[b]))
    assert 0 < pruned.rows_built < full.rows_built


@pytest.mark.slow
@pytest.mark.skipif(not SHARED, reason="../shared/data (or $MICROFACET_DATA) not present")
@pytest.mark.parametrize("path", SHARED, ids=lambda p: p.name.split(".")[0])
def test_shared_materials_keep_their_albedo(path):
    """Issue 10's energy goal at the default albedo weight: the better of the GGX and
    Beckmann fits with a diffuse base has its directional albedo within 10 % of the data's
    at 0/30/60/75 deg (RGB) -- 16 % on violet-acrylic, whose 7-node tables would ring
    without the smoothing penalty of ``TABLE_TV_LIMIT`` (issue 24; the smooth table trades
    albedo at 60 deg: 1.15) -- a white furnace <= 1 and no NaN (the grid-error goal is
    reported in experiments/results/fit_measured.md, not met on every material)."""
    from microfacet.fit.outputs import objective
    from microfacet.metrics import albedo_ratios, uniform_error, white_furnace
    m = mf.measured.load(path)
    start = mf.fit.fit(m, resolution=90)
    fits = {model: fit_analytic(m, model, diffuse=True, start=start) for model in ("ggx", "beckmann")}
    grid, uniform, albedo = fit_error(m, fits), uniform_error(m, fits), albedo_ratios(m, fits)
    best = min(fits, key=lambda k: objective(grid[k], uniform[k], albedo[k], 4.0))
    tolerance = 0.16 if "violet-acrylic" in path.name else 0.10
    assert np.all(np.isfinite(albedo[best])) and np.all(np.abs(albedo[best] - 1.0) <= tolerance)
    assert white_furnace(fits[best]) <= 1.0 + 1e-3
    assert grid[best] < fit_error(m, start.to_ggx())["fit"]


@pytest.mark.slow
@pytest.mark.skipif(not SHARED, reason="../shared/data (or $MICROFACET_DATA) not present")
@pytest.mark.parametrize("path", [p for p in SHARED if "ibiza" not in p.name], ids=lambda p: p.name.split(".")[0])
def test_shared_materials_coat_fit_halves_the_baseline_error(path):
    """Issue 10's grid-error goal (experiments/results/fit_measured.md: met on every shared material but
    cc_ibiza_sunset_rgb): the better GGX / Beckmann fit with a coat (7-node table) and a
    base has at most half the grid error of the baseline, the moment GGX of the
    constraint-only tabulated fit with its own Fresnel table, and its albedo within 10 %
    (gold paint with the Schlick coat: 0.54x)."""
    from microfacet.fit.outputs import objective
    from microfacet.metrics import albedo_ratios, uniform_error
    m = mf.measured.load(path)
    start = mf.fit.fit(m, resolution=90)
    baseline = mf.fit.fit(m, resolution=90, albedo_weight=0.0).to_ggx(resolve_fresnel=False)
    fits = {model: fit_analytic(m, model, diffuse=True, coat=True, start=start) for model in ("ggx", "beckmann")}
    grid, uniform, albedo = fit_error(m, {**fits, "baseline": baseline}), uniform_error(m, fits), albedo_ratios(m, fits)
    best = min(fits, key=lambda k: objective(grid[k], uniform[k], albedo[k], 4.0))
    assert grid[best] <= 0.5 * grid["baseline"]
    assert np.all(np.abs(albedo[best] - 1.0) <= 0.10)


#: Views of the energy checks, up to 89.5 deg (the constraint's last view).
FURNACE_VIEWS = np.radians([0.0, 30.0, 60.0, 75.0, 85.0, 89.0, 89.5])


def max_albedo(brdf, n: int = 256) -> float:
    """The largest directional albedo (RGB) of ``brdf`` itself (its own Fresnel terms and
    base) over :data:`FURNACE_VIEWS`, by :func:`microfacet.validation.sampled_albedo`."""
    from microfacet.validation import sampled_albedo
    return max(float(np.max(sampled_albedo(brdf, brdf, t, n=n))) for t in FURNACE_VIEWS)


#: Every model x Fresnel x (base, coat + base, coat); ``make test`` runs three base-only
#: cases that cover both models and every Fresnel, the rest run under ``--slow`` / CI, but
#: for a Beckmann coat with a tabulated Fresnel over a base (about 100 s: a tenth of the
#: suite's budget), whose terms the GGX coat with a table and the Beckmann coats over a
#: base with Schlick and conductor terms cover.
NO_GAIN_FAST = {("ggx", True, False, "table"), ("beckmann", True, False, "schlick"), ("ggx", True, False, "conductor")}
NO_GAIN_CASES = [pytest.param(*c, marks=() if c in NO_GAIN_FAST else pytest.mark.slow)
                 for c in itertools.product(["ggx", "beckmann"], [True], [False], ["table", "schlick", "conductor"])]
NO_GAIN_CASES += [pytest.param(m, d, True, f, marks=pytest.mark.slow)
                  for m in ("ggx", "beckmann") for d in (True, False) for f in ("table", "schlick", "conductor")
                  if (m, d, f) != ("beckmann", True, "table")]


@pytest.mark.parametrize("model, diffuse, coat, fresnel", NO_GAIN_CASES)
def test_fit_never_reflects_more_than_it_receives(model, diffuse, coat, fresnel):
    """Issue 10: data brighter than a white furnace (a lobe of F0 = 0.3 over a base of
    0.95, albedo ~1.2) is fitted with every term's linear unknowns constrained so that the
    fit's own directional albedo stays <= 1 at every view to 89.5 deg, per channel."""
    truth = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Schlick(0.3)),
                    mf.Lambertian([0.95, 0.9, 0.6]))
    assert max_albedo(truth) > 1.1
    f = fit_analytic(truth, model, diffuse=diffuse, coat=coat, fresnel=fresnel, start=lobe(truth), **FAST)
    assert max_albedo(f) <= 1.0 + 1e-3


def test_energy_constrained_solves_stop_at_their_optimum(monkeypatch):
    """Issue 10 (time): each energy-constrained solve is one dual active-set QP (Goldfarb &
    Idnani, ``quadprog``) after its box QP, not an iteration of box QPs (a dual Newton took
    ~5-130 per solve), and each still meets the constraint it is given."""
    from microfacet.fit import analytic, extract
    truth = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Schlick(0.3)),
                    mf.Lambertian([0.95, 0.9, 0.6]))
    calls = {"box_qp": 0, "solves": 0}
    box_qp, energy_constrained = extract.box_qp, extract._energy_constrained

    def counted_box_qp(*args, **kwargs):
        calls["box_qp"] += 1
        return box_qp(*args, **kwargs)

    def checked_solve(h, g, x0, bounds, albedo, c, diffuse, **kwargs):
        calls["solves"] += 1
        x = energy_constrained(h, g, x0, bounds, albedo, c, diffuse, **kwargs)
        assert np.all(extract._albedo_rows_of(albedo[0], diffuse) @ x <= albedo[1][:, c] * (1.0 + 1e-9))
        return x
    monkeypatch.setattr(extract, "box_qp", counted_box_qp)
    monkeypatch.setattr(analytic, "energy_constrained", checked_solve)
    fit_analytic(truth, "ggx", diffuse=True, start=lobe(truth), **FAST)
    assert calls["solves"] > 10
    assert calls["box_qp"] / calls["solves"] < 3


@pytest.mark.slow
@pytest.mark.skipif(not SHARED, reason="../shared/data (or $MICROFACET_DATA) not present")
@pytest.mark.parametrize("path", SHARED, ids=lambda p: p.name.split(".")[0])
def test_shared_material_fits_never_gain_energy(path):
    """Issue 10 on the measured materials: the default fits with a base (GGX and
    Beckmann, with and without a coat) reflect at most 1 at every view to 89.5 deg
    (paper_white_rgb's GGX + base fit reflected 1.014 at 89.5 deg before the constraint)."""
    m = mf.measured.load(path)
    for model in ("ggx", "beckmann"):
        for coat in (False, True):
            f = fit_analytic(m, model, diffuse=True, coat=coat)
            assert max_albedo(f) <= 1.0 + 1e-3, (model, coat)
