"""The float32 kernels' Beckmann ``Lambda``: ``v (1 + Lambda(v)) ~ P(v) / Q(v)`` on ``[0, 3.5]``
(``microfacet._numba_kernels._LAMBDA_PQ32``): prints the coefficients and the fit's error.

``v (1 + Lambda(v)) = v (1 + erf v) / 2 + exp(-v^2) / (2 sqrt(pi))`` (Table 2.III) is entire, positive
and close to ``v`` for large ``v``; beyond 3.5, ``Lambda < 1.5e-8``, below half a float32 ulp of 1,
and the kernels take ``Lambda = 0``. The fit minimizes the largest relative error (that of ``1 +
Lambda``, the only form the kernels use) on 300 Chebyshev points by Lawson's iteratively
reweighted linearized least squares (``P - f Q`` weighted by ``1 / f``) in 50-digit mpmath
arithmetic, in ``t = v / 3.5``, then rescales to ``v`` (``c_k / 3.5^k``). Degrees (6, 5): 4e-8
(the float64 kernels keep ``exp`` and ``erfcx``: this form would need degrees near (18, 17)).

    .venv/bin/python experiments/beckmann_lambda_float32.py        # ~10 s
"""
from __future__ import annotations

import mpmath as mp

V_MAX, DEGREES = mp.mpf("3.5"), (6, 5)


def lawson_fit(f, m: int, n: int, points: int = 300, iterations: int = 30):
    """``P`` (degree ``m``), ``Q`` (degree ``n``, ``Q(0) = 1``) in ``v`` (lowest coefficient first)
    with ``P / Q ~ f`` on ``[0, V_MAX]`` (minimax in relative error), and the largest relative error
    on the fitting points."""
    t = [(1 - mp.cos(mp.pi * (k + mp.mpf(0.5)) / points)) / 2 for k in range(points)]
    fx = [f(V_MAX * x) for x in t]
    w = [mp.mpf(1)] * points
    for _ in range(iterations):
        a, b = mp.matrix(points, m + 1 + n), mp.matrix(points, 1)
        for i, (x, y) in enumerate(zip(t, fx)):
            s = mp.sqrt(w[i]) / y
            for j in range(m + 1):
                a[i, j] = s * x**j
            for j in range(1, n + 1):
                a[i, m + j] = -s * y * x**j
            b[i] = s * y
        c = mp.qr_solve(a, b)[0]
        p, q = [c[j] for j in range(m + 1)], [mp.mpf(1)] + [c[m + j] for j in range(1, n + 1)]
        err = [abs(mp.polyval(p[::-1], x) / mp.polyval(q[::-1], x) / y - 1) for x, y in zip(t, fx)]
        w = [wi * e for wi, e in zip(w, err)]
        total = sum(w)
        w = [wi / total for wi in w]
    return [ck / V_MAX**k for k, ck in enumerate(p)], [ck / V_MAX**k for k, ck in enumerate(q)], max(err)


if __name__ == "__main__":
    mp.mp.dps = 50
    p, q, err = lawson_fit(lambda v: v * (1 + mp.erf(v)) / 2 + mp.exp(-v * v) / (2 * mp.sqrt(mp.pi)), *DEGREES)
    print(f"# degrees {DEGREES}, largest relative error of the fit {float(err):.1e}")
    print(f"_LAMBDA_PQ32 = ({[float(c) for c in p[::-1]]},\n    {[float(c) for c in q[::-1]]})")
