"""The compiled kernels' Beckmann ``Lambda`` (``microfacet._numba_kernels._beckmann_lambda``): fits the
two rational approximations behind it and prints their coefficients (Horner order, in ``v``).

``Lambda(v) = (exp(-v^2) / (v sqrt(pi)) - erfc(v)) / 2`` (Table 2.III); the kernels use only
``1 + Lambda``, so both fits minimize the largest error of ``Lambda`` relative to ``1 + Lambda``.

- float32 (``_LAMBDA_PQ32``): ``v (1 + Lambda(v)) = v (1 + erf v) / 2 + exp(-v^2) / (2 sqrt(pi)) ~
  P(v) / Q(v)`` on ``[0, 3.5]``, degrees (6, 5), no ``exp``; beyond 3.5 ``Lambda < 1.5e-8``, below
  half a float32 ulp of 1, and the kernels take 0.
- float64 (``_LAMBDA_PQ64``): ``h(v) = v exp(v^2) Lambda(v) = (1 / sqrt(pi) - v erfcx(v)) / 2 ~
  P(v) / Q(v)`` on ``[0, 6]``, degrees (6, 7), so that ``Lambda = exp(-v^2) P / (v Q)``; ``h``'s
  error counts ``exp(-v^2) / (v (1 + Lambda))`` times, so the fit needs full precision only
  near 0 (an unweighted fit of ``erfcx`` to the same 1e-16 needed 17 coefficients, and a quotient
  more for ``1 / v``). Beyond 6 the kernels take ``h(6)`` (``Lambda`` changes by < 1e-19).

Each fit is Lawson's iteratively reweighted linearized least squares (``P - f Q``, weighted as
above) on 300 Chebyshev points, in 50-digit mpmath arithmetic, in ``t = v / v_max``, rescaled to
``v`` (``c_k / v_max^k``) before rounding; the best iterate is kept.

    .venv/bin/python experiments/beckmann_lambda.py        # ~1 min
"""
from __future__ import annotations

import mpmath as mp


def lawson_fit(f, weight, v_max, m: int, n: int, points: int = 300, iterations: int = 40):
    """``P`` (degree ``m``), ``Q`` (degree ``n``, ``Q(0) = 1``), lowest coefficient first, in ``v``,
    minimizing the largest ``|P / Q - f| weight`` on ``[0, v_max]``, and that largest value."""
    t = [(1 - mp.cos(mp.pi * (k + mp.mpf(0.5)) / points)) / 2 for k in range(points)]
    fx, wx = [f(v_max * x) for x in t], [weight(v_max * x) for x in t]
    w, best = [mp.mpf(1)] * points, None
    for _ in range(iterations):
        a, b = mp.matrix(points, m + 1 + n), mp.matrix(points, 1)
        for i, (x, y, s) in enumerate(zip(t, fx, wx)):
            s = mp.sqrt(w[i]) * s
            for j in range(m + 1):
                a[i, j] = s * x**j
            for j in range(1, n + 1):
                a[i, m + j] = -s * y * x**j
            b[i] = s * y
        c = mp.qr_solve(a, b)[0]
        p, q = [c[j] for j in range(m + 1)], [mp.mpf(1)] + [c[m + j] for j in range(1, n + 1)]
        err = [abs(mp.polyval(p[::-1], x) / mp.polyval(q[::-1], x) - y) * s for x, y, s in zip(t, fx, wx)]
        if best is None or max(err) < best[2]:
            best = (p, q, max(err))
        w = [wi * e for wi, e in zip(w, err)]
        total = sum(w)
        w = [wi / total for wi in w]
    p, q, err = best
    return [ck / v_max**k for k, ck in enumerate(p)], [ck / v_max**k for k, ck in enumerate(q)], err


def lam(v):
    """``Lambda(v)`` in mpmath."""
    return (mp.exp(-v * v) / (v * mp.sqrt(mp.pi)) - mp.erfc(v)) / 2


if __name__ == "__main__":
    mp.mp.dps = 50
    r = lambda v: v * (1 + mp.erf(v)) / 2 + mp.exp(-v * v) / (2 * mp.sqrt(mp.pi))      # v (1 + Lambda)
    h = lambda v: (1 / mp.sqrt(mp.pi) - v * mp.exp(v * v) * mp.erfc(v)) / 2            # v exp(v^2) Lambda
    h_weight = lambda v: mp.exp(-v * v) / (v * (1 + lam(v))) if v > 0 else 2 * mp.sqrt(mp.pi)
    for name, f, weight, v_max, degrees in (("_LAMBDA_PQ32", r, lambda v: 1 / r(v), mp.mpf("3.5"), (6, 5)),
                                            ("_LAMBDA_PQ64", h, h_weight, mp.mpf(6), (6, 7))):
        p, q, err = lawson_fit(f, weight, v_max, *degrees)
        print(f"# degrees {degrees}, largest error of Lambda relative to 1 + Lambda {float(err):.1e}")
        print(f"{name} = ({[float(c) for c in p[::-1]]},\n    {[float(c) for c in q[::-1]]})")
