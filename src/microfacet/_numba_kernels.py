"""The Numba kernels of :mod:`microfacet.kernels` (imported, and compiled or loaded from
Numba's on-disk cache, on first use; see that module).

Each public kernel, ``kernel(start, stop, ...)``, works through the pairs ``start:stop``
in blocks of :data:`BLOCK` and writes its outputs in place, with the Fresnel term inside.
A block runs as a few loops over a small scratch array, one per stage (GGX, which has no
Smith loop of its own, in fewer: the loop that reads an input also does the arithmetic
that needs it and writes what it can to the outputs, so that memory waits overlap
arithmetic: GGX sample 14.0 -> 10.5 ms, pdf 2.8 -> 2.2 ms per 10^6 on one core), written with
selects instead of branches, on the operands of quotients and roots rather than their
results (LLVM sinks a quotient used once into the branch of a conditional expression and
then left the loop scalar, 6x slower), reading the ``(n, 3)`` inputs through flat arrays indexed
``o + 3 k + axis`` (:func:`_flat_rows`; views and reshapes made once per call, not per block),
the scratch through 1-D rows and writing outputs through flat arrays: constant strides, so
that LLVM vectorizes each stage that makes no
library call (all of GGX; Beckmann's ``exp`` and ``erfc`` are the kernels' own,
:func:`_exp_neg` and :func:`_erfc_near`, polynomials and bit operations, no table loads, also
in the fixed Halley steps of its visible-slope and ``erfinv`` solves,
:func:`_beckmann_visible_block`, whose rare lanes left to the scalar solvers stay scalar). ``a[k, axis]`` on 2-D arrays (runtime strides) vectorized little: this layout made GGX eval 2x, pdf 2.7x faster. Kernels are
compiled per distribution kind and arithmetic type ``F`` (float64 or float32; constants in
them: :func:`eval_kernel` etc.); the helpers take ``F`` and write their constants as ``F(c)``
(a float literal would promote float32 arithmetic to float64; constants that differ by type,
such as the polynomials of Beckmann's ``exp`` and ``Lambda``, lower degrees in float32, are
chosen by :func:`_of_type`). Beckmann's visible-slope solve stays float64. The model's
parameters come in one record, :class:`microfacet.params.SmithParams` (a named tuple: Numba
reads its fields, ``p.ax``, ``p.fresnel.fp``, as values of a struct; a kernel takes ``(start,
stop, p, inputs..., out)``); its Fresnel kind and shadowing, and the ``/ cos theta_i`` flag,
are tested outside the loops.
The per-element helpers are the NumPy reference's equations, rearranged to save
quotients where that is exact algebra (each docstring says how). ``error_model="numpy"``:
a division by zero gives inf/NaN (then masked), as in NumPy, instead of raising. fastmath
is off in float64 but for ``contract`` in :func:`_smith_block_post` and :func:`_beckmann_eval_block` (the kernels equal the reference to 1e-12; ``contract``/``arcp``/``nsz``
moved some sampled GGX directions by 2e-8 and saved ~10 %); the float32 kernels take
``arcp``, ``afn`` and ``contract`` (:data:`_jit_float32`: eval 1.25x faster), which the
helpers, inlined in Numba's IR (:data:`_inline`), inherit. Inlining doubled the cold
compile (~7 s per kernel and dtype, once per install: ``cache=True``). The block loops of the
eval, pdf and projected kernels run without reference counts (:data:`_loops64`).

Hoisting the per-block ``reshape`` and views out of the block loops (this layout, one core,
per 10^6 pairs, Cu Fresnel, medians of 3 processes against the kernels before): eval float64
GGX 4.16 -> 3.84 ms, Beckmann 7.91 -> 6.15 ms, float32 GGX 1.81 -> 1.56 ms, Beckmann 2.75 -> 2.27
ms; pdf float64 1.88 -> 1.61 / 3.12 -> 2.68 ms, float32 0.92 -> 0.80 / 1.48 -> 1.17 ms; GGX sample
float64 9.6 -> 8.6 ms (the profile of float32 GGX eval had shown 13 % of its samples in the
atomic reference counts and a reshape call per block)."""
from __future__ import annotations

import functools
import math

import numba
import numpy as np

BECKMANN, GGX = 0, 1
IDEAL, SCHLICK, DIELECTRIC, CONDUCTOR, TABULATED = range(5)
_SQRT_PI = math.sqrt(math.pi)
_U_MIN = 2.0**-53
#: The quantile solves ``(1 - u) - (1 - F)`` above this ``u`` (``F - u`` below; the
#: reference switches at 1/2): between, ``F - u`` has an absolute error ~1e-16 and the
#: density is >= ~1e-2, so ``x~`` moves by < 1e-13, and the 12 exps of the complementary
#: CDF near ``cot theta`` are skipped.
_UPPER = 0.99
_GL_T, _GL_W = np.polynomial.legendre.leggauss(12)
_GL_T, _GL_W = 0.5 * (_GL_T + 1.0), 0.5 * _GL_W      # on [0, 1], as in distributions.beckmann

#: ``1/15!, 1/13!, ..., 1/1!`` and ``1/16!, 1/14!, ..., 1/2!`` (Horner order, :func:`_sin_cos`).
_SIN_TAYLOR = np.array([1.0 / math.factorial(n) for n in range(15, 0, -2)])
_COS_TAYLOR = np.array([1.0 / math.factorial(n) for n in range(16, 1, -2)])


def _exp_minimax(degree):
    """Coefficients (Horner order) of ``exp(r) ~ 1 + r + r^2 q(r)`` on ``|r| <= ln 2 / 2``: ``q``
    the Chebyshev interpolant of degree ``degree - 2`` (near minimax) of ``(exp(r) - 1 - r) / r^2``,
    summed from its Taylor series (no cancellation); the two leading coefficients exactly 1."""
    from numpy.polynomial import Chebyshev, Polynomial
    half = 0.5 * math.log(2.0)
    q = Chebyshev.interpolate(lambda r: sum(r**j / math.factorial(j + 2) for j in range(24)), degree - 2,
                              domain=[-half, half])
    return np.concatenate([q.convert(kind=Polynomial).coef[::-1], [1.0, 1.0]])


#: ``ln 2`` split so that ``n ln2_hi`` is exact (:func:`_exp_neg`, :func:`_log_pos`).
_LN2_HI, _LN2_LO = 6.93147180369123816490e-01, 1.90821492927058770002e-10
#: :func:`_exp_neg` per arithmetic type: the polynomial of :func:`_exp_minimax` (float64: degree 11,
#: truncation 2e-17; float32: degree 6, 1e-7 with its roundings), the bound below which ``exp`` is 0
#: (where the value leaves the normal range: ``exp(-708) = 3.3e-308``, ``exp(-87) = 1.6e-38``),
#: ``ln 2`` split and ``1.5 2^p`` (``x + c - c`` rounds ``x`` to an integer).
_EXP64 = (_exp_minimax(11), -708.0, _LN2_HI, _LN2_LO, 1.5 * 2.0**52)
_EXP32 = (_exp_minimax(6).astype(np.float32), np.float32(-87.0), np.float32(0.693359375),
          np.float32(-2.12194440e-4), np.float32(1.5 * 2.0**23))


_jit = numba.njit(cache=True, nogil=True, error_model="numpy")
#: The float32 kernels: approximate reciprocals and square roots refined by a Newton step
#: (``arcp``, ``afn``: ``vrsqrt14ps``, a few ulps) and fused multiply-adds (``contract``).
_jit_float32 = numba.njit(cache=True, nogil=True, error_model="numpy", fastmath={"arcp", "afn", "contract"})
#: For the per-element helpers of the kernels: Numba inlines them into its own IR (LLVM
#: would not inline them two calls deep), so that they take the kernel's fastmath flags.
_inline = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
#: Loops whose latency is chains of multiply-adds: fused (``contract``, the only fast-math flag).
_jit_contract = numba.njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
#: The block loops of the eval, pdf and projected kernels (float64; float32 with :data:`_jit_float32`'s
#: flags), compiled without reference counts (Numba's ``_nrt=False``; their arrays are made by the
#: kernel that calls them, :func:`_scratch`): with them, each array an inlined helper takes, and each
#: view, cost an atomic increment and decrement per block (13 % of float32 GGX eval's profile samples;
#: eval, Cu Fresnel, one core, per 10^6 pairs, medians of 4 processes: float32 GGX 1.59 -> 1.55 ms,
#: Beckmann 2.56 -> 2.28 ms, float64 Beckmann 7.3 -> 6.3 ms). The sample kernel keeps its own arrays
#: and its reference counts: with its ten rows as arguments, float32 GGX sample took 3.1 -> 3.6 ms.
_loops64 = numba.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
_loops32 = numba.njit(cache=True, nogil=True, error_model="numpy", _nrt=False, fastmath={"arcp", "afn", "contract"})


# ------------------------------------------------------------------------ helpers
@_inline
def _warp(p, s1, kx, ky, kz):
    """``(a^2 + b^2, c)`` of the warped direction ``k' = (a, b, c)`` of ``k`` (Eq. 3.3) for the
    record ``p`` (:class:`microfacet.params.SmithParams`), ``s1 = sqrt(1 - rho^2)``."""
    a = p.ax * kx + p.rho * p.ay * ky
    b = p.ay * s1 * ky
    return a * a + b * b, kz - kx * p.xn - ky * p.yn


@_inline
def _view_root(F, kind, r2, co):
    """The square root in :func:`_smith_pre`'s terms of the warped view ``o' = (a, b, c_o)``,
    ``r2 = a^2 + b^2`` (``c_o = 1`` where ``c_o <= 0``): GGX ``q_o = sqrt(c_o^2 + r2)``, Beckmann
    ``sqrt(r2)``; apart, so that the sample kernel takes it from its first loop."""
    co = co if co > F(0.0) else F(1.0)
    return math.sqrt(co * co + r2) if kind == GGX else math.sqrt(r2)


@_inline
def _smith_pre(F, kind, shadowing, root_o, co, r2_i, ci):
    """Smith terms of the warped view ``o' = (a, b, c_o)``, ``root_o`` its :func:`_view_root`, and light
    (``r2_i``, ``c_i``) (Eq. 3.3, Table 2.III), evaluated at ``c = 1`` where ``c <= 0`` (callers
    mask those): ``(A, W, c)`` with ``A = 2 c_o (1 + Lambda_o)``, ``W / c = 2 c_o (1 + Lambda_o +
    Lambda_i)`` (``Lambda_i = 0`` without shadowing), so that ``D / (4 A(o)) = D / (2 A)``,
    ``D G / (4 z_o) = D c / (2 W)`` and ``G / G1(o) = c A / W``. GGX: ``1 + Lambda_k =
    (c_k + q_k) / (2 c_k)``, ``q_k = sqrt(c_k^2 + r2_k)``, so ``A = c_o + q_o``, ``W = c_i q_o +
    c_o q_i``, ``c = c_i`` (no quotient). Beckmann: the arguments ``v_k = c_k / sqrt(r2_k)`` of
    Lambda and ``c = 1``; :func:`_smith_post` finishes them in a loop of its own."""
    co = co if co > F(0.0) else F(1.0)
    lit = shadowing & (ci > F(0.0))
    ci = ci if lit else F(1.0)
    if kind == GGX:
        qi = math.sqrt(ci * ci + (r2_i if lit else F(0.0)))
        return co + root_o, ci * root_o + co * qi, ci
    return co / root_o, ci / math.sqrt(r2_i if lit else F(0.0)), F(1.0)     # 1 / 0 = inf


def _float_type(row):
    """The scalar type (``np.float64`` or ``np.float32``) of a float ``row``, in compiled code."""


@numba.extending.overload(_float_type, inline="always")
def _float_type_impl(row):
    if row.dtype == numba.types.float32:
        return lambda row: np.float32
    return lambda row: np.float64


@_inline
def _beckmann_lambda(F, v):
    """Beckmann ``Lambda(v) = (exp(-v^2) / (v sqrt(pi)) - erfc(v)) / 2`` (Table 2.III; 0 at ``v = inf``)
    in ``F`` arithmetic, only ``1 + Lambda`` being used, from the rational fits of
    ``experiments/beckmann_lambda.py``. Float64: ``exp(-v^2) P(x) / (v Q(x))``, ``x = min(v, 6)``
    (:data:`_LAMBDA_PQ64`: ``P / Q ~ v exp(v^2) Lambda``), 5.5e-16 of ``1 + Lambda`` against mpmath
    (the ``exp(-v^2) erfcx(v)`` it replaces, with a 17-degree polynomial and two quotients more:
    5e-16; Beckmann eval 8.4-8.8 -> 8.2 ms, pdf 3.75-3.80 -> 3.3-3.4 ms per 10^6 pairs on one
    core). Float32: ``P(v) / (v Q(v)) - 1`` (:data:`_LAMBDA_PQ32`: ``P / Q ~ v (1 + Lambda)``, no
    ``exp``), 0 beyond 3.5 (where ``Lambda < 1.5e-8``): 3.3e-7 of ``1 + Lambda`` with its roundings
    (2.8 float32 ulps, near ``v = 3``, where ``P / (v Q)`` is close to 1; the ``exp`` and ``erfcx``
    polynomials it replaces: 1.7e-7; float32 Beckmann eval 3.1 -> 2.75 ms, pdf 1.65 -> 1.45 ms)."""
    if _of_type(F, False, True):                     # float32 (the other branch is compiled out)
        x = min(v, F(_LAMBDA_MAX32))
        lam = _horner(_LAMBDA_PQ32[0], x) / (x * _horner(_LAMBDA_PQ32[1], x)) - F(1.0)
        return lam if (lam > F(0.0)) & (v < F(_LAMBDA_MAX32)) else F(0.0)
    x = min(v, F(_LAMBDA_MAX64))
    lam = _exp_neg(F, -v * v) * _horner(_LAMBDA_PQ64[0], x) / (v * _horner(_LAMBDA_PQ64[1], x))
    return lam if lam > F(0.0) else F(0.0)


#: The rational fits of :func:`_beckmann_lambda` (``experiments/beckmann_lambda.py`` fits them and
#: says how), coefficients in Horner order: float32 ``v (1 + Lambda(v)) ~ P / Q`` on ``[0, 3.5]``,
#: degrees (6, 5), 2.9e-8; float64 ``v exp(v^2) Lambda(v) ~ P / Q`` on ``[0, 6]``, degrees (6, 7),
#: 8.1e-17 (both: the largest error of ``Lambda`` relative to ``1 + Lambda``).
_LAMBDA_PQ32 = (np.array([0.006631364056879357, 0.02067196852187177, 0.05122319870200464,
                          0.1294337854867778, 0.3234519727408768, 0.4749117736455794,
                          0.282094799931098], np.float32),
                np.array([0.0063344341707721845, 0.026126461222640333, 0.009143358508372078,
                          0.30416559795295844, -0.08893187058398526, 1.0], np.float32))
_LAMBDA_PQ64 = (np.array([5.059204435254722e-08, 0.00041165461182469324, 0.005521121319540883,
                          0.033282710759376395, 0.11798546306570451, 0.23799856214075163,
                          0.28209479177387814]),
                np.array([0.0029283636850550416, 0.03901244036926986, 0.24150344189631062,
                          0.887798224883823, 2.073417351510806, 3.0552292990837078,
                          2.616136786858251, 1.0]))
_LAMBDA_MAX32, _LAMBDA_MAX64 = np.float32(3.5), 6.0


@_inline
def _horner(c, x):
    """``c[0] x^(n-1) + ... + c[n-1]`` by Horner's rule (``c`` in Horner order)."""
    p = c[0]
    for j in range(1, c.shape[0]):
        p = c[j] + x * p
    return p


def _of_type(F, c64, c32):
    """``c32`` if ``F`` is ``np.float32``, else ``c64``, chosen when the caller is compiled (for
    constants, :data:`_EXP64` etc., that differ by arithmetic type)."""


@numba.extending.overload(_of_type, inline="always")
def _of_type_impl(F, c64, c32):
    if F.instance_type == numba.types.float32:
        return lambda F, c64, c32: c32
    return lambda F, c64, c32: c64


def _two_to(F, n):
    """``2^n`` for an integer-valued ``F`` ``n`` in ``[-1022, 0]`` (float32: ``[-126, 0]``), built from
    its bits (the table of ``2^n`` it replaces was a gather)."""


@numba.extending.overload(_two_to, inline="always")
def _two_to_impl(F, n):
    I, bits, bias = (np.int32, 23, 127) if F.instance_type == numba.types.float32 else (np.int64, 52, 1023)

    def two_to(F, n):
        return I((I(n) + I(bias)) << I(bits)).view(F)
    return two_to


@_inline
def _exp_neg(F, x):
    """``exp(x)`` for ``x <= 0`` in ``F`` arithmetic, arithmetic only, so that a loop calling it
    vectorizes: ``x = n ln 2 + r``, ``|r| <= ln 2 / 2`` (``n`` rounded by adding and subtracting
    ``1.5 2^p``: no reassociation allowed), ``exp(r)`` by :func:`_exp_minimax`'s polynomial, times
    ``2^n`` (:func:`_two_to`). Relative error 1 ulp (2.2e-16; float32 1.2e-7). Flushed to 0 below
    :data:`_EXP64`'s bound, -708, where the value would leave the normal range (float32: -87), and
    for NaN: a subnormal result or operand costs a microcode assist on this CPU (a loop of float32
    ``exp`` whose lanes reach subnormals, 0.17 -> 0.55 ns per element; float32 Beckmann eval, one
    core, 4.45 -> 3.9 ms per 10^6 pairs with this bound)."""
    poly, lo, ln2_hi, ln2_lo, rnd = _of_type(F, _EXP64, _EXP32)
    xc = x if x > lo else lo
    xc = xc if xc < F(0.0) else F(0.0)
    n = (xc * F(1.0 / math.log(2.0)) + rnd) - rnd
    r = (xc - n * ln2_hi) - n * ln2_lo
    return _horner(poly, r) * _two_to(F, n) if x > lo else F(0.0)


#: :func:`_erfc_near` fits ``erfcx`` on ``[0, _ERFCX_MAX]`` as a polynomial in ``s = 2 (tau - tau_M)
#: / (1 - tau_M) - 1 = _ERFCX_A / (_ERFCX_K + v) - _ERFCX_B`` in ``[-1, 1]`` (``tau = K / (K + v)``,
#: ``tau_M`` its value at the end; ``K = 4`` converges faster than 2: degree 17 instead of 19).
_ERFCX_MAX, _ERFCX_K = 6.0, 4.0
_TAU_M = _ERFCX_K / (_ERFCX_K + _ERFCX_MAX)
_ERFCX_A, _ERFCX_B = 2.0 * _ERFCX_K / (1.0 - _TAU_M), (1.0 + _TAU_M) / (1.0 - _TAU_M)


def _erfcx_decimal(nodes, digits=50):
    """``erfcx(v) = exp(v^2) - 2 / sqrt(pi) sum_n 2^n v^(2n+1) / (2n+1)!!`` (the series of ``exp(v^2)
    erf(v)``, positive terms) at ``v = _ERFCX_A / (s + _ERFCX_B) - _ERFCX_K`` of each float ``s`` of
    ``nodes``, all in ``digits``-digit decimal arithmetic (``pi`` by the Gauss-Legendre AGM), rounded
    to float64. (SciPy's ``erfcx`` is 8e-16 off near 0, and ``v`` rounded to float64 moves the value
    by 5e-16; through the interpolant of :func:`_erfcx_poly` either cost 4e-15.)"""
    import decimal
    D = decimal.Decimal
    out = []
    with decimal.localcontext() as ctx:
        ctx.prec = digits + 10
        a, b, t, p = D(1), D(2).sqrt() / 2, D(1) / 4, D(1)
        for _ in range(8):                           # digits double per step
            a, b, t, p = (a + b) / 2, (a * b).sqrt(), t - p * ((a - b) / 2) ** 2, 2 * p
        sqrt_pi = ((a + b) ** 2 / (4 * t)).sqrt()
        for s in nodes:
            x = D(_ERFCX_A) / (D(float(s)) + D(_ERFCX_B)) - D(_ERFCX_K)
            term = total = x
            n = 0
            while term > total.scaleb(-digits - 10):
                n += 1
                term = term * 2 * x * x / (2 * n + 1)
                total += term
            out.append(float((x * x).exp() - 2 * total / sqrt_pi))
    return np.array(out)


def _erfcx_poly(degree):
    """Coefficients (Horner order) in ``s`` of :data:`_ERFCX_A` of ``erfcx(v) = exp(v^2) erfc(v)``,
    ``v`` in ``[0, _ERFCX_MAX]`` (``erfcx ~ tau / (K sqrt(pi))`` for large ``v``: smooth in ``tau``):
    the interpolant (near minimax) through :func:`_erfcx_decimal` at the Chebyshev points, in
    exact rational arithmetic (Newton's divided differences, expanded to the monomial basis), then
    rounded: its coefficients sum to 1.00001 in absolute value, so Horner's rule is well
    conditioned. (Chebyshev coefficients in float64 accumulated 4e-15 at ``v = 0``.)"""
    from fractions import Fraction
    x = [Fraction(float(t)) for t in np.polynomial.chebyshev.chebpts1(degree + 1)]
    c = [Fraction(float(y)) for y in _erfcx_decimal(x)]
    for j in range(1, degree + 1):                   # divided differences
        for i in range(degree, j - 1, -1):
            c[i] = (c[i] - c[i - 1]) / (x[i] - x[i - j])
    p = [c[degree]]                                  # Newton form to monomials, highest first
    for k in range(degree - 1, -1, -1):
        p = [a - x[k] * b for a, b in zip(p + [Fraction(0)], [Fraction(0)] + p)]
        p[-1] += c[k]
    return np.array([float(a) for a in p])


#: :func:`_erfcx_poly` of degree 17 (8e-16 relative to ``v = 4``), built on import.
_ERFCX_POLY = _erfcx_poly(17)


@_inline
def _erfc_near(F, v, e):
    """``erfc(v) = e erfcx(v)`` for ``v >= 0`` given ``e = exp(-v^2)`` in ``F`` arithmetic (the
    visible-slope solve's and the glint kernels', float64): Horner's rule on :data:`_ERFCX_POLY` (8e-16
    relative to ``v = 4`` and absolute, measured against mpmath), ``erfcx(6) e`` beyond 6 (absolute
    error below 2e-17); arithmetic only, no table gathers (a piecewise Taylor series' 16 per call
    bound the loops that called it)."""
    s = F(_ERFCX_A) / (F(_ERFCX_K) + min(max(v, F(0.0)), F(_ERFCX_MAX))) - F(_ERFCX_B)
    return e * _horner(_ERFCX_POLY, s)


@_inline
def _smith_post(F, v_o, v_i, co):
    """Beckmann ``(A, W)`` of :func:`_smith_pre` from its ``v_o``, ``v_i`` and ``c_o`` in ``F`` arithmetic."""
    co = co if co > F(0.0) else F(1.0)
    lam_o = _beckmann_lambda(F, v_o)
    return F(2.0) * co * (F(1.0) + lam_o), F(2.0) * co * (F(1.0) + lam_o + _beckmann_lambda(F, v_i))


@_inline
def _ndf_pre(F, kind, p, s1, hx, hy, hz):
    """``D(h) = P_std(x / z, y / z) / (z^4 alpha_x alpha_y sqrt(1 - rho^2))`` for ``hz > 0``
    (Eq. 2.11, 3.2, Table 2.II, division-free) as ``(e, scale)`` for :func:`_ndf_over`: GGX
    ``(pi r^2, 1 / det)``, ``r = z^2 + x^2 + y^2``; Beckmann ``((x^2 + y^2) / (2 z^2),
    1 / (pi z^4 det))``, whose ``exp`` :func:`_ndf_post` takes."""
    ax, ay, rho, xn, yn = p.ax, p.ay, p.rho, p.xn, p.yn
    inv_det = F(1.0) / (ax * ay * s1)                   # loop invariants: hoisted
    x = (-hx - xn * hz) * (F(1.0) / ax)
    y = (ax * (-hy - yn * hz) - rho * ay * (-hx - xn * hz)) * inv_det
    if kind == GGX:
        r = hz * hz + x * x + y * y
        return F(math.pi) * r * r, inv_det
    z2 = hz * hz
    return F(0.5) * (x * x + y * y) / z2, inv_det / (F(math.pi) * z2 * z2)


@_inline
def _ndf_post(F, kind, e):
    """The transcendental factor of :func:`_ndf_pre` (Beckmann ``exp(-e)`` in ``F`` arithmetic; GGX ``e``)."""
    if kind == GGX:
        return e
    return _exp_neg(F, -e)


#: float32 Beckmann: ``exp(-(x^2 + y^2) / z^2) = e^2`` below ``2^-120`` (float32's normal range ends at
#: ``2^-126``) is flushed to 0 (:func:`_ndf_over`), so that ``D = e^2 scale / den`` is 0 where it would
#: be ``< 2^-120 scale / den`` (about 1e-34 for the ``scale / den`` of typical pairs), as a renderer's
#: flush-to-zero mode does: at 10^6 uniform pairs (alpha 0.2, 0.5) 11 % of the float32 values fell
#: in the subnormal range, and each such lane cost its vector a microcode assist (eval, one core,
#: 3.9 -> 3.4 ms; pdf 1.93 -> 1.77 ms).
_GAUSS_FTZ32 = 2.0**-60


@_inline
def _ndf_over(F, kind, e, scale, den):
    """``D scale / den`` from :func:`_ndf_post`'s ``e`` (one quotient): GGX ``scale / (e den)``;
    Beckmann's ``exp(-(x^2 + y^2) / z^2)`` is the square of ``e = exp(-(x^2 + y^2) / (2 z^2))``,
    so that ``D`` stays representable where the exponential alone underflows but ``/ z^4``
    brings it back (as the reference's ``exp(-(x^2 + y^2) / z^2 - 4 log z)`` does). In float32, ``e``
    below :data:`_GAUSS_FTZ32` is flushed to 0 (see there)."""
    if kind == GGX:
        return scale / (e * den)
    e = e if e >= _of_type(F, 0.0, np.float32(_GAUSS_FTZ32)) else F(0.0)
    return e * scale * e / den


@_inline
def _pdf_and_ratio(F, kind, area, w, c, e, scale, visible):
    """``(pdf, G / G1(o))`` of a sampled pair from :func:`_smith_pre`'s ``(A, W, c)`` (after
    :func:`_smith_post`) and :func:`_ndf_post`'s ``e`` and ``scale`` (0 where invalid):
    ``D / (4 A(o)) = D / (2 A)`` and ``c A / W`` (Eq. 2.17, 2.23); 0 where the pdf is 0 or
    ``wi`` is not ``visible``."""
    e, scale, den = _guard(F, (scale > F(0.0)) & (e > F(0.0)), e, scale, F(2.0) * area)
    p = _ndf_over(F, kind, e, scale, den)
    g = (p > F(0.0)) & visible
    return p, (c * area if g else F(0.0)) / (w if g else F(1.0))


@_inline
def _projected_over(F, kind, e, f, c, w):
    """``D G / (4 z_o) [/ z_i] = D c / (2 W)`` of :func:`_projected_block` from :func:`_ndf_post`'s
    ``e``, the NDF's ``scale`` ``f`` (0 where invalid, ``/ z_i`` taken) and :func:`_smith_pre`'s
    ``c`` and ``W`` (after :func:`_smith_post`)."""
    e, scale, den = _guard(F, (f > F(0.0)) & (e > F(0.0)), e, f * c, F(2.0) * w)
    return _ndf_over(F, kind, e, scale, den)


@_inline
def _guard(F, valid, e, scale, den):
    """The arguments of :func:`_ndf_over` where ``valid``, else ``(1, 0, 1)`` (which give 0):
    the operands of a quotient are selected, not its result, since LLVM sinks a quotient
    used once into the branch of a conditional expression and then leaves the loop scalar."""
    return (e if valid else F(1.0)), (scale if valid else F(0.0)), (den if valid else F(1.0))


@_inline
def _schlick(F, f0, f90, c):
    """Schlick's ``F = F0 + (F90 - F0)(1 - c)^5`` (Table 2.I for ``F90 = 1``; :class:`~microfacet.fresnel.Schlick`)."""
    m = F(1.0) - min(max(c, F(0.0)), F(1.0))
    m2 = m * m
    return f0 + (f90 - f0) * (m2 * m2 * m)


@_inline
def _dielectric(F, eta, c):
    """Dielectric Fresnel reflectance (Table 2.I; :class:`~microfacet.fresnel.Dielectric`),
    1 under total internal reflection."""
    c = min(max(c, F(0.0)), F(1.0))
    g2 = eta * eta + c * c - F(1.0)
    g = math.sqrt(max(g2, F(0.0)))
    a = (g - c) / (g + c)
    b = (c * (g + c) - F(1.0)) / (c * (g - c) + F(1.0))
    f = F(0.5) * a * a * (F(1.0) + b * b)
    return F(1.0) if (g2 < F(0.0)) | (not abs(f) < F(math.inf)) else f


@_inline
def _conductor(F, eta, k, c):
    """Conductor Fresnel reflectance (:func:`microfacet.fresnel.conductor_reflectance`) with
    its two quotients in one: ``(R_s + R_p) / 2 = R_s t3 / (t3 + t4)``, ``R_s = (A - B) / (A + B)``."""
    c = min(max(c, F(0.0)), F(1.0))
    c2 = c * c
    s2 = F(1.0) - c2
    t1 = eta * eta - k * k - s2
    a2b2 = math.sqrt(t1 * t1 + F(4.0) * eta * eta * k * k)
    ac2 = F(2.0) * c * math.sqrt(max(F(0.5) * (a2b2 + t1), F(0.0)))
    t3, t4 = a2b2 * c2 + s2 * s2, ac2 * s2
    return (a2b2 + c2 - ac2) * t3 / ((a2b2 + c2 + ac2) * (t3 + t4))


@_jit
def _interp(tx, tv, ch, c):
    """``np.interp(c, tx, tv[:, ch])`` (clamped at the ends): one channel of
    :class:`~microfacet.fresnel.Tabulated`."""
    n = tx.shape[0]
    if c <= tx[0]:
        return tv[0, ch]
    if c >= tx[n - 1]:
        return tv[n - 1, ch]
    lo, hi = 0, n - 1
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if tx[mid] <= c:
            lo = mid
        else:
            hi = mid
    return (tv[hi, ch] - tv[lo, ch]) / (tx[hi] - tx[lo]) * (c - tx[lo]) + tv[lo, ch]


@_inline
def _fresnel_block(F, f, c_row, s_row, out, o, m):
    """``out[o + 3 k + ch] = F_ch(c_row[k]) * s_row[k]`` for ``k < m`` (a flat output, from its
    element ``o``): the Fresnel term of the record ``f`` (:class:`microfacet.params.FresnelParams`:
    kind ``fk``, ``fp[0]`` is ``f0`` or ``eta``, ``fp[1]`` ``k``; ``tx``, ``tv`` the
    :class:`~microfacet.fresnel.Tabulated` grid and values), one loop
    over ``k`` per kind (the choice outside it: one loop with the choice inside, which LLVM
    does not unswitch, took GGX Cu eval 4.7 -> 18 ms and float32 2.0 -> 6.0 ms per 10^6 pairs
    on one core) with the three channels inside, writing the
    output as it goes (interleaved stores; rows and a second pass to interleave them cost
    GGX sample 1 ms (7 %) more per 10^6 pairs on one core), so that the analytic terms vectorize."""
    fk, fp, tx, tv = f.kind, f.fp, f.tx, f.tv
    p0, p1, p2 = fp[0, 0], fp[0, 1], fp[0, 2]
    q0, q1, q2 = fp[1, 0], fp[1, 1], fp[1, 2]
    o = max(o, 0)                                    # (see _flat_rows)
    if fk == IDEAL:
        for k in range(m):
            s = s_row[k]
            out[o + 3 * k], out[o + 3 * k + 1], out[o + 3 * k + 2] = s, s, s
    elif fk == SCHLICK:
        for k in range(m):
            c, s = c_row[k], s_row[k]
            out[o + 3 * k] = _schlick(F, p0, q0, c) * s
            out[o + 3 * k + 1] = _schlick(F, p1, q1, c) * s
            out[o + 3 * k + 2] = _schlick(F, p2, q2, c) * s
    elif fk == DIELECTRIC:
        for k in range(m):
            c, s = c_row[k], s_row[k]
            out[o + 3 * k] = _dielectric(F, p0, c) * s
            out[o + 3 * k + 1] = _dielectric(F, p1, c) * s
            out[o + 3 * k + 2] = _dielectric(F, p2, c) * s
    elif fk == CONDUCTOR:
        for k in range(m):
            c, s = c_row[k], s_row[k]
            out[o + 3 * k] = _conductor(F, p0, q0, c) * s
            out[o + 3 * k + 1] = _conductor(F, p1, q1, c) * s
            out[o + 3 * k + 2] = _conductor(F, p2, q2, c) * s
    else:
        for k in range(m):
            for ch in range(3):
                out[o + 3 * k + ch] = _interp(tx, tv, ch, c_row[k]) * s_row[k]


@_inline
def _projected_block(kind, p, shadowing, mode, block, rows, tops):
    """``rows[0][k] = o.h`` (if ``oh_row``) and ``dst[od + k] = D G / (4 z_o) [/ z_i]`` of the pairs ``k < m``
    of the flat ``wi``, ``wo`` from their elements ``oi``, ``oo`` (``3 k + axis``: :func:`_flat_rows`;
    ``block = (wi, oi, wo, oo, m, dst, od)``), the distribution ``kind``, in the arithmetic type of
    ``rows`` (:func:`_float_type`), with the flags ``shadowing`` and ``mode = (divide_cos_i, measure, oh_row,
    smith)`` (constants at each call but ``divide_cos_i``, and ``shadowing`` and ``smith`` of eval;
    ``shadowing`` apart, so that the pdf's literal ``False`` reaches :func:`_smith_block_post`, which Numba
    then compiles for that constant, as it did before the flags were a tuple)
    (Eq. 2.1 with F = 1: ``D / (4 c_o (1 + Lambda_i + Lambda_o))``, the NDF of Eq. 3.2
    and the height-correlated Smith G with the warped directions of Eq. 3.3; ``Lambda_i = 0``
    without shadowing, which makes it the visible-normal pdf ``D / (4 A(o))`` of Eq. 2.17),
    0 where invalid (see ``_projected_numpy``), for the record ``p`` (:class:`microfacet.params.SmithParams`;
    ``shadowing`` apart: the pdf takes ``False`` whatever ``p.shadowing``). Uses the six scratch ``rows`` (1-D arrays of ``F``,
    made once per kernel call: an array view made per block costs two atomic reference counts).
    Returns ``tops = (top_i, top_o)`` updated, if ``measure``, with the unit-length deviations of ``wi`` and
    ``wo``: the largest :func:`_bits_of` of their :func:`_deviation_at`, taken in this loop in lanes of
    ``F``'s width (rows and a pass over them, as the sample kernel's, took Beckmann eval 8-10 %
    longer; int64 lanes in the float32 loop, 13-30 %). Without ``oh_row`` (the pdf), ``h = wi + wo`` is
    not normalized: ``D`` is homogeneous of degree -4 in ``h`` (Eq. 2.11: ``P(x/z, y/z) / z^4``),
    so ``D(h / |h|) = |h|^4 D(h)`` takes a product where ``1 / |h|`` takes a root and a quotient."""
    F = _float_type(rows[0])
    divide_cos_i, measure, oh_row, smith = mode
    wi, oi, wo, oo, m, dst, od = block
    top_i, top_o = tops
    s1 = math.sqrt(F(1.0) - p.rho * p.rho)
    oh_r, a_r, w_r, e_r, f_r, co_r = rows
    oi, oo, od = max(oi, 0), max(oo, 0), max(od, 0)  # (see _flat_rows)
    for k in range(m):
        ji, jo = oi + 3 * k, oo + 3 * k
        ix, iy, iz = F(wi[ji]), F(wi[ji + 1]), F(wi[ji + 2])
        ox, oy, oz = F(wo[jo]), F(wo[jo + 1]), F(wo[jo + 2])
        if measure:
            top_i = max(top_i, _bits_of(_deviation_at(F, wi, ji)))
            top_o = max(top_o, _bits_of(_deviation_at(F, wo, jo)))
        hx, hy, hz = ix + ox, iy + oy, iz + oz
        n2 = hx * hx + hy * hy + hz * hz
        if oh_row:
            inv = F(1.0) / math.sqrt(n2 if n2 > F(0.0) else F(math.inf))       # 0 at n2 = 0
            hx, hy, hz = hx * inv, hy * inv, hz * inv
        oh = ox * hx + oy * hy + oz * hz
        r2, co = _warp(p, s1, ox, oy, oz)
        r2_i, ci = _warp(p, s1, ix, iy, iz)
        ok = ((iz > F(0.0)) & (oz > F(0.0)) & (oh > F(0.0)) & (hz > F(0.0)) & (co > F(0.0))
              & ((ci > F(0.0)) | (not shadowing)))
        e, scale = _ndf_pre(F, kind, p, s1, hx, hy, hz if hz > F(0.0) else F(1.0))
        if oh_row:
            oh_r[k] = oh
        else:
            scale *= n2 * n2
        area, w, c = _smith_pre(F, kind, shadowing, _view_root(F, kind, r2, co), co, r2_i, ci)
        f = (scale if ok else F(0.0)) / (iz if divide_cos_i & ok else F(1.0))
        if kind == GGX:                              # no Smith loop of its own: the value here
            dst[od + k] = _projected_over(F, kind, e, f, c, w)
        else:
            a_r[k], e_r[k], f_r[k], co_r[k] = area, e, f, co
            if shadowing:
                w_r[k] = w
    if kind != GGX and smith:
        _smith_block_post(kind, shadowing, a_r, w_r, e_r, co_r, m)
        for k in range(m):
            dst[od + k] = _projected_over(F, kind, e_r[k], f_r[k], F(1.0), w_r[k] if shadowing else a_r[k])
    return top_i, top_o


@_inline
def _beckmann_value(rows, k):
    """Pair ``k``'s ``D G / (4 z_o) [/ z_i]`` from the float64 rows ``(o.h, v_o, v_i, e, f, c_o)`` that
    :func:`_projected_block` leaves without ``smith`` (:func:`_smith_post`, :func:`_ndf_post`, :func:`_projected_over`)."""
    F = np.float64
    w = _smith_post(F, rows[1][k], rows[2][k], rows[5][k])[1]
    return _projected_over(F, BECKMANN, _ndf_post(F, BECKMANN, rows[3][k]), rows[4][k], F(1.0), w)


@_jit_contract
def _beckmann_eval_block(f, rows, out, o, m):
    """float64 Beckmann eval with shadowing and an ideal or conductor Fresnel term, after
    :func:`_projected_block` without ``smith``: the Smith terms, the NDF's ``exp``, the value and the
    Fresnel term in one loop (:func:`_beckmann_value`, as :func:`_fresnel_block`), so that the ``exp``
    and ``Lambda`` polynomials (multiply-adds) overlap the Fresnel term's roots and quotients. One
    core, per 10^6 pairs, alternated, medians of 3 processes: Cu 5.85 -> 5.18 ms (-12 %), ideal
    5.29 -> 3.93 ms (-25 %). Each fused loop costs ~2.5 s of cold compile (6.8 -> 11.7 s for this
    kernel), so only the float64 Beckmann eval kernel compiles it (``fused`` in :func:`eval_kernel`),
    and not for the dielectric term (-6 %); fused, Schlick and tabulated terms took 7 % and 16 %
    longer, float32 13 %. ``contract``, as :func:`_smith_block_post`. ``f``: the Fresnel record
    (:class:`microfacet.params.FresnelParams`)."""
    fk, fp = f.kind, f.fp
    p0, p1, p2 = fp[0, 0], fp[0, 1], fp[0, 2]
    q0, q1, q2 = fp[1, 0], fp[1, 1], fp[1, 2]
    oh, o = rows[0], max(o, 0)                       # (see _flat_rows)
    if fk == IDEAL:
        for k in range(m):
            s = _beckmann_value(rows, k)
            out[o + 3 * k], out[o + 3 * k + 1], out[o + 3 * k + 2] = s, s, s
    else:
        for k in range(m):
            c, s = oh[k], _beckmann_value(rows, k)
            out[o + 3 * k] = _conductor(np.float64, p0, q0, c) * s
            out[o + 3 * k + 1] = _conductor(np.float64, p1, q1, c) * s
            out[o + 3 * k + 2] = _conductor(np.float64, p2, q2, c) * s


@_jit_contract
def _smith_block_post(kind, shadowing, v_o, v_i, e, co, m):
    """Beckmann: :func:`_smith_post` on the rows ``v_o``, ``v_i`` (then ``A``, ``W``) and ``co``, and
    :func:`_ndf_post` on ``e`` (its ``exp`` and ``erfc``, in a loop of their own, over 1-D rows: the
    loop vectorizes; in the rows' arithmetic type, :func:`_float_type`: float32 rows took float64
    arithmetic before, at half the SIMD width and the float64 polynomials' degrees; with
    shadowing, in cache, one core: float32 5.8 -> 0.9 ns per pair, float64 5.1 -> 2.7 with the
    ``exp`` and ``erfcx`` polynomials :func:`_beckmann_lambda` took then); nothing for GGX. Without
    ``shadowing`` (``Lambda_i = 0``, ``W = A``: the pdf) one ``Lambda`` per pair, not two, and
    ``v_i`` (``W``) is left as it is: callers read ``A`` for it.
    Not inlined, so that it keeps its own fastmath ``contract``: its polynomials are chains of
    multiply-adds whose latency bounds the loop, and fused they take Beckmann eval from 21 to
    18 ms per 10^6 pairs on one core (the kernels' worst relative error against the
    reference is unchanged, 8e-13)."""
    if kind != GGX:
        F = _float_type(v_o)
        if shadowing:
            for k in range(m):
                v_o[k], v_i[k] = _smith_post(F, v_o[k], v_i[k], co[k])
                e[k] = _ndf_post(F, kind, e[k])
        else:
            for k in range(m):
                v_o[k] = _smith_post(F, v_o[k], F(math.inf), co[k])[0]
                e[k] = _ndf_post(F, kind, e[k])


#: ``2 / (2 k + 1)``, ``k = 10 ... 0`` (Horner order in ``f^2``, :func:`_log_pos`).
_ATANH_TAYLOR = np.array([2.0 / (2 * k + 1) for k in range(10, -1, -1)])


@_inline
def _log_pos(x):
    """``log(x)`` for a normal float64 ``x > 0``, arithmetic and bit operations only, so that a
    loop calling it vectorizes: ``x = 2^n m``, ``m`` in ``[sqrt(1/2), sqrt(2))`` from the bits,
    ``log m = 2 atanh(f)``, ``f = (m - 1) / (m + 1)``, ``|f| <= 0.172``, by its Taylor series
    ``2 sum f^(2k+1) / (2k + 1)`` to ``f^21`` (truncation below 1e-18), plus ``n ln 2``."""
    b = np.float64(x).view(np.int64)
    m = np.int64((b & np.int64(0xFFFFFFFFFFFFF)) | np.int64(0x3FF0000000000000)).view(np.float64)
    big = m > math.sqrt(2.0)
    n = float((b >> np.int64(52)) - np.int64(1023)) + (1.0 if big else 0.0)
    m = 0.5 * m if big else m
    f = (m - 1.0) / (m + 1.0)
    return n * _LN2_HI + (n * _LN2_LO + f * _horner(_ATANH_TAYLOR, f * f))


#: Giles' coefficients (Horner order) for ``w = -log(1 - y^2) < 5`` (in ``w - 2.5``) and beyond
#: (in ``sqrt(w) - 3``), :func:`_erfinv_guess`.
_GILES_CENTRAL = np.array([2.81022636e-08, 3.43273939e-07, -3.5233877e-06, -4.39150654e-06, 0.00021858087,
                           -0.00125372503, -0.00417768164, 0.246640727, 1.50140941])
_GILES_TAIL = np.array([-0.000200214257, 0.000100950558, 0.00134934322, -0.00367342844, 0.00573950773,
                        -0.0076224613, 0.00943887047, 1.00167406, 2.83297682])


@_inline
def _erfinv_guess(y):
    """Giles' single-precision ``erfinv(y)``, ``|y| < 1`` ("Approximating the erfinv function",
    GPU Computing Gems 2011; relative error <= 1.25e-7 measured on 10^6 uniform ``y``), its two
    branches as selects of the coefficients, with :func:`_log_pos`: a loop calling it vectorizes."""
    w = -_log_pos((1.0 - y) * (1.0 + y))
    central = w < 5.0
    z = w - 2.5 if central else math.sqrt(w) - 3.0
    p = _GILES_CENTRAL[0] if central else _GILES_TAIL[0]
    for j in range(1, _GILES_CENTRAL.shape[0]):
        p = (_GILES_CENTRAL[j] if central else _GILES_TAIL[j]) + p * z
    return p * y


@_inline
def _erfinv_step(y, x, f, exp_x2):
    """Halley's step on ``erf(x) = y`` from ``x`` given its residual ``f`` (``erf(|x|) - |y|``,
    or ``(1 - |y|) - erfc(|x|)`` for ``|y| > 1/2``) and ``exp_x2 = exp(x^2)``: ``(x', d)``, ``d =
    f / f'`` the Newton step, ``x' = sign(y) (|x| - d / (1 + |x| d))`` (``f'' / f' = -2 |x|``)."""
    ax = abs(x)
    d = f * (0.5 * _SQRT_PI) * exp_x2
    return (1.0 if y >= 0.0 else -1.0) * (ax - d / (1.0 + ax * d)), d


@_jit
def _erfinv(y):
    """``erfinv(y)`` for ``|y| < 1``: :func:`_erfinv_guess` and :func:`_erfinv_step` on
    ``erf(x) = y`` (on ``erfc(|x|) = 1 - |y|`` for ``|y| > 1/2``, exact there, so the tails keep
    precision): one, more where ``1 - |y| < 2^-24``, outside the guess's range. A step of ``d``
    leaves an error ``~ K d^3``, Halley's constant ``K = (f2 / 2 f1)^2 - f3 / 6 f1 = (x^2 + 1) / 3``
    (``f_n`` the derivatives of ``erf``), below 4e-18 relative for ``|d| <= 2e-7 |x|``, ``|x| <= 6``."""
    x = _erfinv_guess(y)
    for _ in range(6):                                # 1 step, more beyond float32's range
        ax = abs(x)
        f = (1.0 - abs(y)) - math.erfc(ax) if abs(y) > 0.5 else math.erf(ax) - abs(y)
        x, d = _erfinv_step(y, x, f, math.exp(ax * ax))
        if abs(d) <= 2e-7 * ax:                       # this step left < 4e-18 relative
            break
    return x


@_jit
def _cdf(x, t, exp_x):
    """Unnormalized visible-slope CDF (``distributions.beckmann._cdf``), given ``exp_x = exp(-x^2)``."""
    return math.erfc(-x) + t * exp_x / _SQRT_PI


@_jit
def _ccdf(x, t, a, erfc_a, exp_a, exp_x):
    """Unnormalized complementary CDF (``distributions.beckmann._ccdf``: closed form, or the
    12-point Gauss-Legendre rule where ``a - x < 1``), given ``exp_x = exp(-x^2)``."""
    if a - x < 1.0:
        dn = a - x
        acc = 0.0
        for j in range(_GL_T.shape[0]):
            s = dn * _GL_T[j]
            acc += _GL_W[j] * s * math.exp(-(a - s) ** 2)
        return 2.0 * t / _SQRT_PI * dn * acc
    return math.erfc(x) - erfc_a + t * (exp_a - exp_x) / _SQRT_PI


def _q2_table(n_cos=64, n_s=256):
    """Nodes ``s`` and table ``Q2(u(s), cos theta)`` (:func:`distributions.beckmann.visible_slope_quantile`,
    the NumPy reference) on ``cos theta = 0, 1/(n_cos-1), ..., 1`` and ``n_s`` uniform ``s``, with
    ``s = sign(2u - 1) sqrt(-ln(4 u (1 - u)))`` (Giles' ``w`` of :func:`_erfinv`: ``s ~ x~`` in
    both Gaussian tails, ``~ 2u - 1`` near ``1/2``), ``|s| <= S = s(2^-53)``; ``u(s) = q / (2 (1 +
    sqrt(1 - q)))``, ``q = exp(-s^2)``, below ``1/2`` and ``1 - u(|s|)`` above."""
    from .distributions.beckmann import visible_slope_quantile
    s_max = math.sqrt(-math.log(4.0 * _U_MIN * (1.0 - _U_MIN)))
    s = np.linspace(-s_max, s_max, n_s)
    q = np.exp(-s * s)
    um = q / (2.0 * (1.0 + np.sqrt(1.0 - q)))
    u = np.where(s < 0.0, um, 1.0 - um)
    return s_max, np.ascontiguousarray(visible_slope_quantile(u[None, :], np.linspace(0.0, 1.0, n_cos)[:, None]))


#: Initial guesses of :func:`_visible_slope_quantile` (:func:`_q2_table`, 64 x 256, built on import).
_Q2_S, _Q2_TAB = _q2_table()


@_inline
def _visible_slope_guess(u, c):
    """Bilinear interpolation of :data:`_Q2_TAB` at ``(cos theta, s(u))`` (:func:`_q2_table`): an
    initial guess for ``Q2(u)`` (median error 3e-5, worst 0.12 on 10^6 samples with tails), with
    :func:`_log_pos` and table loads: a loop calling it vectorizes."""
    y = 2.0 * u - 1.0
    s = math.sqrt(-_log_pos((1.0 - y) * (1.0 + y)))
    n_c, n_s = _Q2_TAB.shape
    fc = c * (n_c - 1)
    fs = (min(max(s if y >= 0.0 else -s, -_Q2_S), _Q2_S) + _Q2_S) * ((n_s - 1) / (2.0 * _Q2_S))
    ic, js = min(int(fc), n_c - 2), min(int(fs), n_s - 2)
    wc, ws = fc - ic, fs - js
    return ((1.0 - wc) * ((1.0 - ws) * _Q2_TAB[ic, js] + ws * _Q2_TAB[ic, js + 1])
            + wc * ((1.0 - ws) * _Q2_TAB[ic + 1, js] + ws * _Q2_TAB[ic + 1, js + 1]))


@_inline
def _q2_step(x, r, t, e):
    """Newton's step ``f / f'`` on the visible-slope CDF residual ``r`` at ``x`` (``f'`` the
    density ``2 e (1 - x t) / sqrt(pi)``, ``e = exp(-x^2)``) and the point ``x'`` of Halley's
    step ``f / f' / (1 - f f'' / (2 f'^2))`` (``f'' / f' = -2x - t / (1 - x t)``) where its
    denominator exceeds 1/2, else Newton's (the operand selected, not the quotient)."""
    step = r / (2.0 * e * (1.0 - x * t) / _SQRT_PI)
    den = 1.0 - 0.5 * step * (-2.0 * x - t / (1.0 - x * t))
    return step, x - step / (den if den > 0.5 else 1.0)


@_jit
def _visible_slope_quantile(u, cos_theta):
    """``Q2(u)`` of the standard Beckmann visible x-slope (Table 2.V): the safeguarded
    Newton-bisection of ``distributions.beckmann.visible_slope_quantile``, per element (no
    compaction), from the tabulated guess of :func:`_visible_slope_guess`, with Halley's
    step ``f / f' / (1 - f f'' / (2 f'^2))`` where its denominator exceeds 1/2 (else
    Newton's) and the stopping test on the Newton step ``f / f'``: 2.1 iterations on
    average over uniform ``(u, cos theta)`` (the Newton-bisection from Mitsuba's fitted
    guess took 4.3)."""
    u = min(max(u, _U_MIN), 1.0 - _U_MIN)
    a, t = _visible_view(cos_theta)
    erfc_a, exp_a = math.erfc(a), math.exp(-a * a)
    z = (2.0 - erfc_a) + t * exp_a / _SQRT_PI        # erfc(-a) = 2 - erfc(a), a >= 0
    upper = u >= _UPPER                              # the upper tail: residual of 1 - F
    target = ((1.0 - u) if upper else u) * z
    lo, hi = -8.0, min(a, 8.0)
    x = min(max(_visible_slope_guess(u, min(max(cos_theta, 1e-12), 1.0)), lo), hi)
    for _ in range(64):
        e = math.exp(-x * x)
        r = target - _ccdf(x, t, a, erfc_a, exp_a, e) if upper else _cdf(x, t, e) - target
        if r < 0.0:
            lo = x
        if r > 0.0:
            hi = x
        step, xn = _q2_step(x, r, t, e)
        converged = (abs(step) <= 1e-12 * max(1.0, abs(x))) or r == 0.0   # on the Newton step
        if not converged and not (lo < xn < hi):
            xn = 0.5 * (lo + hi)
        done = converged or hi - lo <= 4e-16 * max(1.0, abs(x))
        x = xn
        if done:
            break
    return x


@_inline
def _sin_cos(F, x):
    """``(sin x, cos x)`` for ``|x| <= pi/4``: Taylor series to ``x^15`` and ``x^16``
    (truncation below 5e-17), arithmetic only, so that a loop calling it vectorizes."""
    x2 = x * x
    sn, cs = F(_SIN_TAYLOR[0]), F(_COS_TAYLOR[0])
    for j in range(1, 8):                            # Horner
        sn = F(_SIN_TAYLOR[j]) - x2 * sn
        cs = F(_COS_TAYLOR[j]) - x2 * cs
    return x * sn, F(1.0) - x2 * cs


@_inline
def _view_angles(F, kind, p, s1, wo, j):
    """``(cos theta, cos phi, sin phi, c_o, root)`` of the warped view ``o' = (a, b, c_o)`` (Eq. 3.3)
    of the direction ``wo[j:j + 3]`` of a flat ``wo`` for the record ``p``, ``root`` its :func:`_view_root`:
    ``theta`` is 0 where ``a = b = 0``, ``pi/2`` where ``c_o <= 0``."""
    ox, oy, oz = F(wo[j]), F(wo[j + 1]), F(wo[j + 2])
    a = p.ax * ox + p.rho * p.ay * oy
    b = p.ay * s1 * oy
    co = oz - ox * p.xn - oy * p.yn
    c = max(co, F(0.0))
    r2 = a * a + b * b
    root = _view_root(F, kind, r2, co)
    q = root if kind == GGX else math.sqrt(r2 + c * c)          # |o'| where c_o > 0
    inv_r = F(1.0) / math.sqrt(r2)
    cos_t = (c if r2 > F(0.0) else F(1.0)) / (q if r2 > F(0.0) else F(1.0))
    return cos_t, (a * inv_r if r2 > F(0.0) else F(1.0)), (b * inv_r if r2 > F(0.0) else F(0.0)), co, root


@_inline
def _ggx_visible_std(F, u0, u1, cos_t):
    """Standard GGX visible normal for a view at ``theta`` in the xz plane (Heitz's closed
    form, ``GGX.sample_visible_std``) from the concentric disk map of ``geometry`` (its
    ``r cos phi``, ``r sin phi`` with ``phi = pi/2 - psi`` as ``r sin psi``, ``r cos psi``), with
    selects instead of branches."""
    c = min(max(cos_t, F(0.0)), F(1.0))
    s = math.sqrt((F(1.0) - c) * (F(1.0) + c))      # geometry.sin_from_cos
    a, b = F(2.0) * u0 - F(1.0), F(2.0) * u1 - F(1.0)
    first = abs(a) > abs(b)                          # phi = pi/4 b/a; else phi = pi/2 - pi/4 a/b
    r = a if first else b
    q = (b if first else a) / (r if r != F(0.0) else F(1.0))
    sn, cs = _sin_cos(F, F(math.pi / 4) * q)
    t1, t2 = r * (cs if first else sn), r * (sn if first else cs)
    w = F(0.5) * (F(1.0) + c)
    t2 = (F(1.0) - w) * math.sqrt(max(F(0.0), F(1.0) - t1 * t1)) + w * t2
    tz = math.sqrt(max(F(0.0), F(1.0) - t1 * t1 - t2 * t2))
    return s * tz - c * t2, t1, c * tz + s * t2


#: Lanes of :func:`_beckmann_visible_block` with ``|x~|`` or ``|y~|`` beyond this go to the scalar
#: solvers: :func:`_erfc_near` keeps 4e-15 relative below it, which the Gaussian tails need.
_TAIL = 4.0
#: ``2 / sqrt(pi) (-1)^n / (n! (2n + 1))``, ``n = 13 ... 0`` (Horner order, :func:`_erf_small`).
_ERF_TAYLOR = np.array([2.0 / _SQRT_PI * (-1) ** n / (math.factorial(n) * (2 * n + 1)) for n in range(13, -1, -1)])


@_inline
def _erf_small(x):
    """``erf(x)`` for ``|x| <= 1/2`` by its Taylor series ``2 / sqrt(pi) sum (-1)^n x^(2n+1) /
    (n! (2n + 1))`` to ``n = 13`` (truncation below 1e-19 relative), arithmetic only."""
    return x * _horner(_ERF_TAYLOR, x * x)


@_inline
def _q2_cdf_step(x, t, target):
    """:func:`_q2_step` on ``F(x) - target``, ``F = erfc(-x) + t exp(-x^2) / sqrt(pi)`` (the
    unnormalized CDF, :func:`_cdf`) with :func:`_exp_neg` and :func:`_erfc_near` (``erfc(-x) =
    2 - erfc(x)``; ``|x| <= _TAIL``): arithmetic only."""
    e = _exp_neg(np.float64, -x * x)
    ec = _erfc_near(np.float64, abs(x), e)
    return _q2_step(x, (ec if x < 0.0 else 2.0 - ec) + t * e / _SQRT_PI - target, t, e)


@_inline
def _visible_view(cos_theta):
    """``(a, t) = (cot theta, tan theta)`` of the visible-slope CDF, ``cos theta`` clamped to
    ``[1e-12, 1]`` (as in :func:`_visible_slope_quantile`)."""
    c = min(max(cos_theta, 1e-12), 1.0)
    s = math.sqrt((1.0 - c) * (1.0 + c))            # geometry.sin_from_cos
    return c / s, s / c


@_jit_contract
def _beckmann_visible_block(u, ou, cos_row, normal, scratch, m):
    """``normal = (mx, my, mz)``, rows: the standard Beckmann visible normal for a view at ``theta`` in the
    xz plane (``Beckmann.sample_visible_std``: ``x~ = Q2(u[ou + 2 k])``, ``y~ = erfinv(2 u[ou + 2 k + 1] -
    1)``, ``cos theta = cos_row[k]``) for ``k < m``, in float64 (``scratch = (gx, gy, ok_x, ok_y)``, rows). The
    guesses :func:`_visible_slope_guess` and :func:`_erfinv_guess` in a loop of their own (it
    vectorizes since their ``log`` is :func:`_log_pos`, not the library's: the block 24 -> 20 ns
    per view in cache, Beckmann sample 50 -> 34 ms per 10^6 on one core); then, in loops that vectorize (:func:`_exp_neg`, :func:`_erfc_near`
    with ``erfc(-x) = 2 - erfc(x)``, :func:`_erf_small`; fastmath ``contract``: its latency is
    chains of multiply-adds, 51 -> 46 ms per 10^6 views) three of
    :func:`_visible_slope_quantile`'s steps on ``F - u z`` (two left 10 % of the lanes to the
    scalar solve, three 1 %), one loop over ``k`` per step (in one loop, each iteration a chain
    of three dependent steps, the loop was bound by their latency: 10.4 instead of 3 x 1.7 ns
    per view), and one of :func:`_erfinv`'s, with their stopping tests after the last. The lanes
    that fail them, lie in the upper tail (``u >= _UPPER``, solved on the complementary CDF) or
    beyond :data:`_TAIL` are solved again by those scalar functions."""
    mx, my, mz = normal
    gx, gy, ok_x, ok_y = scratch
    uz = ok_x                                        # u z until the flags of x~ replace it
    ou = max(ou, 0)                                  # (see _flat_rows)
    for k in range(m):                               # guesses
        u0 = min(max(float(u[ou + 2 * k]), _U_MIN), 1.0 - _U_MIN)
        gx[k] = _visible_slope_guess(u0, min(max(float(cos_row[k]), 1e-12), 1.0))
        gy[k] = _erfinv_guess(2.0 * min(max(float(u[ou + 2 * k + 1]), _U_MIN), 1.0 - _U_MIN) - 1.0)
    for k in range(m):                               # u z, the first Halley step of x~, y~'s step
        u0 = min(max(float(u[ou + 2 * k]), _U_MIN), 1.0 - _U_MIN)
        a, t = _visible_view(float(cos_row[k]))
        e_a = _exp_neg(np.float64, -a * a)
        uz[k] = u0 * ((2.0 - _erfc_near(np.float64, a, e_a)) + t * e_a / _SQRT_PI)
        gx[k] = _q2_cdf_step(min(max(gx[k], -8.0), min(a, 8.0)), t, uz[k])[1]
        y = 2.0 * min(max(float(u[ou + 2 * k + 1]), _U_MIN), 1.0 - _U_MIN) - 1.0
        ay = abs(gy[k])
        e = _exp_neg(np.float64, -ay * ay)
        f = (1.0 - abs(y)) - _erfc_near(np.float64, ay, e) if abs(y) > 0.5 else _erf_small(min(ay, 0.5)) - abs(y)
        gy[k], d = _erfinv_step(y, gy[k], f, 1.0 / e)
        ok_y[k] = 1.0 if (abs(d) <= 2e-7 * ay) & (ay < _TAIL) else 0.0
    for k in range(m):                               # the second
        gx[k] = _q2_cdf_step(gx[k], _visible_view(float(cos_row[k]))[1], uz[k])[1]
    for k in range(m):                               # the third, and the stopping test
        u0 = min(max(float(u[ou + 2 * k]), _U_MIN), 1.0 - _U_MIN)
        a, t = _visible_view(float(cos_row[k]))
        step, x = _q2_cdf_step(gx[k], t, uz[k])
        ok_x[k] = 1.0 if ((u0 < _UPPER) & (abs(step) <= 1e-12 * max(1.0, abs(x)))
                          & (abs(x) < _TAIL) & (x < min(a, 8.0))) else 0.0
        gx[k] = x
    for k in range(m):                               # the rare rest, scalar
        if ok_x[k] == 0.0:
            gx[k] = _visible_slope_quantile(float(u[ou + 2 * k]), float(cos_row[k]))
        if ok_y[k] == 0.0:
            gy[k] = _erfinv(2.0 * min(max(float(u[ou + 2 * k + 1]), _U_MIN), 1.0 - _U_MIN) - 1.0)
    for k in range(m):
        x, y = gx[k], gy[k]
        inv = 1.0 / math.sqrt(1.0 + x * x + y * y)
        mx[k], my[k], mz[k] = -x * inv, -y * inv, inv


# ------------------------------------------------------------------------ kernels
#: Directions per block: a kernel call ``kernel(start, stop, ...)`` works through the pairs
#: ``start:stop`` in blocks of this many, in a ``(rows, BLOCK)`` scratch array (in cache),
#: one loop per stage, so that the stages without library calls vectorize and the extra
#: memory is independent of N.
#: The caller runs ranges on threads (:func:`microfacet.kernels._launch_ranges`): Numba's
#: ``prange`` keeps these loops from vectorizing.
BLOCK = 256


#: Bits of float64 and float32 ``inf``: non-negative floats, then inf, then NaN, order as their
#: integer bits.
_INF_BITS, _INF_BITS32 = np.int64(0x7FF0000000000000), np.int64(0x7F800000)
#: The float32 kernels' deviations (:func:`_deviation_at` in float32) are within this of the exact
#: ones where they are below 1/2: ``x^2 + y^2 + z^2 = s`` is computed to ``3 2^-24 s`` (``s < 3/2``),
#: the subtraction of 1 is exact.
_SLACK32 = 2.0**-20


@_inline
def _deviation_at(F, w, j):
    """``| |w_k|^2 - 1 |`` of the direction ``w[j:j + 3]`` of a flat ``w`` (:func:`_flat_rows`)
    in ``F`` arithmetic: in float64 as :func:`microfacet.geometry.unit_deviation` (same operations,
    same order: the same value); in float32 within :data:`_SLACK32` of it. The kernels compute it in
    the loop that reads the block, so that ``MicrofacetBRDF``'s unit-length check takes no pass of
    its own (float64 arithmetic in the float32 kernels' loops halved their SIMD width, GGX eval
    2.0 -> 2.8 ms per 10^6)."""
    x, y, z = F(w[j]), F(w[j + 1]), F(w[j + 2])
    return abs(x * x + y * y + z * z - F(1.0))


def _bits(row):
    """``(row viewed as integers of its width, the bits of inf, the slack)`` of a float64 or float32
    ``row`` of deviations (:data:`_INF_BITS`, :data:`_SLACK32`)."""


@numba.extending.overload(_bits, inline="always")
def _bits_impl(row):
    if row.dtype == numba.types.float32:
        return lambda row: (row.view(np.int32), _INF_BITS32, _SLACK32)
    return lambda row: (row.view(np.int64), _INF_BITS, 0.0)


def _bits_of(x):
    """The integer bits of a float64 or float32 ``x`` (int64 or int32, as wide as ``x``; see
    :data:`_INF_BITS`)."""


@numba.extending.overload(_bits_of, inline="always")
def _bits_of_impl(x):
    if x == numba.types.float32:
        return lambda x: np.float32(x).view(np.int32)
    return lambda x: np.float64(x).view(np.int64)


@_inline
def _no_bits(F):
    """The start (0) of a maximum of :func:`_bits_of` of ``F`` values."""
    return _of_type(F, np.int64(0), np.int32(0))


@_inline
def _max_bits(bits, m, top):
    """``max(top, bits[:m])``, ``bits`` the integer view (:func:`_bits`, made once per kernel call) of a
    non-negative row (:func:`_deviation_at`): see :data:`_INF_BITS` (an integer maximum vectorizes,
    a float one that must see NaN does not)."""
    for k in range(m):
        top = max(top, np.int64(bits[k]))
    return top


@_jit
def _deviation(top, row):
    """The float whose bits are ``top`` (:func:`_max_bits`, or a maximum of :func:`_bits_of`) as float64,
    ``inf`` for NaN and inf; plus :data:`_SLACK32` for a float32 ``row`` (then an upper bound of the
    exact deviation, where that is below 1/2). ``row[0]`` is overwritten."""
    bits, inf_bits, slack = _bits(row)
    if top >= inf_bits:
        return math.inf
    bits[0] = top
    return np.float64(row[0]) + slack


@_inline
def _outside_unit(u):
    """1 if ``u`` lies outside ``[0, 1]`` (NaN included), else 0: the range check of
    ``MicrofacetBRDF.sample``'s uniforms, counted as the sample kernel reads them."""
    return 0 if (u >= 0.0) & (u <= 1.0) else 1


@_jit
def _unit_deviation(w):
    """``max | |w|^2 - 1 |`` over the rows of a C-contiguous ``w (n, 3)``; ``inf`` if one is
    NaN or inf (:func:`_deviation_at`, :func:`_max_bits` on a flat view, a block at a time)."""
    a = w.reshape(w.size)
    row = np.empty(BLOCK)
    bits = _bits(row)[0]
    top = np.int64(0)
    for j0 in range(0, w.shape[0], BLOCK):
        m = min(BLOCK, w.shape[0] - j0)
        for k in range(m):
            row[k] = _deviation_at(np.float64, a, 3 * (j0 + k))
        top = _max_bits(bits, m, top)
    return _deviation(top, row)


def _flat_rows(a, flat, j0, m, scratch):
    """Rows ``j0:j0 + m`` of ``a (n, w)`` as ``(b, o)``, a flat C-contiguous ``b`` and the element
    ``o >= 0`` where they start (``b[o + w k + axis]``): ``flat`` (:func:`_flat`) and ``w j0`` for a
    C-contiguous ``a``, else (a broadcast or strided ``a``) a copy into ``scratch`` (``w BLOCK``
    elements) and 0. The loops index the result with a constant stride, which LLVM vectorizes
    (interleaved loads); ``a[k, axis]`` has runtime strides, which it does not. An offset, not a
    view per block: a view costs two atomic reference counts, and a reshape per block a call
    (~13 % of float32 GGX eval). The loops take ``max(o, 0)``: an offset not known to be
    non-negative makes Numba wrap negative indices around, and the loops stop vectorizing."""
    return np.ascontiguousarray(a[j0:j0 + m]).reshape(-1), 0      # compiled: the overload below


def _flat(a):
    """``a (n, w)`` as one flat array, made once per kernel call (C layout; else ``a`` itself, which
    :func:`_flat_rows` copies a block at a time)."""


@numba.extending.overload(_flat, inline="always")
def _flat_impl(a):
    if a.layout == "C":
        return lambda a: a.reshape(a.size)
    return lambda a: a


@numba.extending.overload(_flat_rows, inline="always")
def _flat_rows_impl(a, flat, j0, m, scratch):
    if a.layout == "C":
        def view(a, flat, j0, m, scratch):
            return flat, max(a.shape[1] * j0, 0)
        return view

    def copy(a, flat, j0, m, scratch):
        w = a.shape[1]
        for k in range(m):
            for c in range(w):
                scratch[w * k + c] = a[j0 + k, c]
        return scratch, 0
    return copy


#: The block loops of the kernels made so far, by ``(kernel, kind, dtype name)`` (:func:`_loops`).
_LOOPS = {}


def _loops(key):
    """Compiles block loops in the arithmetic of ``key = (kernel, kind, dtype name)``
    (:data:`_loops64`, :data:`_loops32`) and keeps them for :func:`_call_loops`."""
    def decorate(function):
        _LOOPS[key] = (_loops64 if key[2] == "float64" else _loops32)(function)
        return _LOOPS[key]
    return decorate


def _call_loops(key, *args):
    """``_LOOPS[key](*args)`` in compiled code, ``key`` a constant tuple: the kernels call their loops
    through it, not as a closure variable, which Numba's cache keys by a pickle that differs from
    one process to the next (the kernels were compiled again in every process, 0.2-0.5 s each)."""


@numba.extending.overload(_call_loops)
def _call_loops_impl(key, *args):
    if isinstance(key, numba.types.BaseTuple) and all(isinstance(t, numba.types.Literal) for t in key.types):
        loops = _LOOPS[tuple(t.literal_value for t in key.types)]
        return lambda key, *args: loops(*args)


@_jit
def _scratch(F, wi, wo):
    """What the block loops of the eval, pdf and projected kernels use, made once per call: the
    six scratch rows of ``F`` (:func:`_projected_block`), copy buffers for non-contiguous inputs
    (:func:`_flat_rows`) and flat views."""
    buf = np.empty((6, BLOCK), F)
    rows = (buf[0], buf[1], buf[2], buf[3], buf[4], buf[5])
    return rows, np.empty(3 * BLOCK, wi.dtype), np.empty(3 * BLOCK, wo.dtype), _flat(wi), _flat(wo)


@_jit
def _deviations(tops, scratch):
    """The unit-length deviations of ``wi`` and ``wo`` (:func:`_deviation`) from the loops' largest bits
    ``tops``, through a scratch row that is free once the loops are done."""
    row = scratch[0][0]
    return _deviation(np.int64(tops[0]), row), _deviation(np.int64(tops[1]), row)


@functools.cache
def projected_kernel(kind, dtype=np.float64):
    """Kernel ``(start, stop, p, wi, wo, divide_cos_i, out)`` writing ``o.h`` and ``D G / (4 z_o)
    [/ z_i]`` per pair (:func:`_projected_block`) into ``out = (oh_out, s_out)``, for the record ``p``
    (:class:`microfacet.params.SmithParams`; its Fresnel term unused) of the distribution ``kind``
    in ``dtype`` arithmetic (the kernels are compiled per kind and ``dtype``, constants in them;
    the record's scalars are of ``dtype``)."""
    F = np.dtype(dtype).type
    key = ("projected", kind, np.dtype(dtype).name)

    @_loops(key)
    def loops(start, stop, p, wi, wo, divide_cos_i, out, scratch):
        oh_out, s_out = out
        rows, si, so, wi_f, wo_f = scratch
        oh_r = rows[0]
        for j0 in range(start, stop, BLOCK):
            m = min(BLOCK, stop - j0)
            (bi, oi), (bo, oo) = _flat_rows(wi, wi_f, j0, m, si), _flat_rows(wo, wo_f, j0, m, so)
            _projected_block(kind, p, p.shadowing, (divide_cos_i, False, True, True), (bi, oi, bo, oo, m, s_out, j0),
                             rows, (_no_bits(F), _no_bits(F)))
            for k in range(m):
                oh_out[max(j0, 0) + k] = oh_r[k]

    @_jit
    def kernel(start, stop, p, wi, wo, divide_cos_i, out):
        _call_loops(key, start, stop, p, wi, wo, divide_cos_i, out, _scratch(F, wi, wo))
    return kernel


@functools.cache
def pdf_kernel(kind, dtype=np.float64):
    """Kernel ``(start, stop, p, wi, wo, out)`` writing the visible-normal sampling density
    ``D(h) / (4 A(o))`` (Eq. 2.17, ``A(o) = c_o (1 + Lambda(o))``) per pair for the record ``p``
    (:class:`microfacet.params.SmithParams`; shadowing and Fresnel term unused); returns the
    largest unit-length deviations of its ``wi`` and ``wo`` (:func:`_deviation`)."""
    F = np.dtype(dtype).type
    key = ("pdf", kind, np.dtype(dtype).name)

    @_loops(key)
    def loops(start, stop, p, wi, wo, out, scratch):
        rows, si, so, wi_f, wo_f = scratch
        top_i, top_o = _no_bits(F), _no_bits(F)
        for j0 in range(start, stop, BLOCK):
            m = min(BLOCK, stop - j0)
            (bi, oi), (bo, oo) = _flat_rows(wi, wi_f, j0, m, si), _flat_rows(wo, wo_f, j0, m, so)
            top_i, top_o = _projected_block(kind, p, False, (False, True, False, True), (bi, oi, bo, oo, m, out, j0),
                                            rows, (top_i, top_o))
        return top_i, top_o

    @_jit
    def kernel(start, stop, p, wi, wo, out):
        scratch = _scratch(F, wi, wo)
        return _deviations(_call_loops(key, start, stop, p, wi, wo, out, scratch), scratch)
    return kernel


@functools.cache
def eval_kernel(kind, dtype=np.float64):
    """Kernel ``(start, stop, p, wi, wo, divide_cos_i, out)`` writing ``F D G / (4 z_o) [/ z_i]``
    RGB per pair into ``out (n, 3)`` (Eq. 2.1, Listing 2.2) for the record ``p``
    (:class:`microfacet.params.SmithParams`); returns the deviations of its ``wi`` and ``wo``, as
    :func:`pdf_kernel`."""
    F = np.dtype(dtype).type
    key = ("eval", kind, np.dtype(dtype).name)
    fused = kind == BECKMANN and F is np.float64     # (a constant: Numba prunes `if fused` elsewhere)

    @_loops(key)
    def loops(start, stop, p, wi, wo, divide_cos_i, out, scratch):
        rows, si, so, wi_f, wo_f = scratch
        top_i, top_o = _no_bits(F), _no_bits(F)
        f = p.fresnel
        later = p.shadowing & ((f.kind == IDEAL) | (f.kind == CONDUCTOR))
        for j0 in range(start, stop, BLOCK):
            m = min(BLOCK, stop - j0)
            (bi, oi), (bo, oo) = _flat_rows(wi, wi_f, j0, m, si), _flat_rows(wo, wo_f, j0, m, so)
            top_i, top_o = _projected_block(kind, p, p.shadowing, (divide_cos_i, True, True, not (fused and later)),
                                            (bi, oi, bo, oo, m, rows[1], 0), rows, (top_i, top_o))
            if fused and later:
                _beckmann_eval_block(f, rows, out, 3 * j0, m)
            else:
                _fresnel_block(F, f, rows[0], rows[1], out, 3 * j0, m)
        return top_i, top_o

    @_jit
    def kernel(start, stop, p, wi, wo, divide_cos_i, out):
        scratch = _scratch(F, wi, wo)
        return _deviations(_call_loops(key, start, stop, p, wi, wo, divide_cos_i, out.reshape(out.size), scratch),
                           scratch)
    return kernel


@functools.cache
def sample_kernel(kind, dtype=np.float64):
    """Kernel ``(start, stop, p, u, wo, out)``, ``out = (wi_out, weight_out, pdf_out)``, of visible-normal
    sampling of ``f_r cos theta_i`` (Sec. 2.2, 3.2; ``MicrofacetBRDF.sample``) for the record ``p``
    (:class:`microfacet.params.SmithParams`):
    ``wi`` reflected about ``h ~ D_o``, weight ``F G / G1(o)`` (Eq. 2.23), pdf ``D(h) / (4 A(o))``;
    returns how many of its ``u`` lie outside ``[0, 1]`` and the deviation of its ``wo``."""
    F = np.dtype(dtype).type

    @(_jit if F is np.float64 else _jit_float32)
    def kernel(start, stop, p, u, wo, out):
        wi_out, weight_out, pdf_out = out
        shadowing, xn, yn = p.shadowing, p.xn, p.yn
        ax, ay, rho = p.ax, p.ay, p.rho
        s1 = math.sqrt(F(1.0) - rho * rho)
        buf = np.empty((10, BLOCK), F)
        bk = np.empty((4, BLOCK))                    # Beckmann's float64 rows
        gx, gy, ok_x, ok_y = bk[0], bk[1], bk[2], bk[3]
        su, so = np.empty(2 * BLOCK, u.dtype), np.empty(3 * BLOCK, wo.dtype)
        u_f, wo_f = _flat(u), _flat(wo)
        outside, top_o, dev_o = 0, np.int64(0), buf[9]
        bits_o = _bits(dev_o)[0]
        wi_b, weight_flat = wi_out.reshape(wi_out.size), weight_out.reshape(weight_out.size)
        r0, r1, r2, r3, r4, r5, r6 = buf[0], buf[1], buf[2], buf[3], buf[4], buf[5], buf[6]
        r7, r8 = buf[7], buf[8]
        for j0 in range(start, stop, BLOCK):
            m = min(BLOCK, stop - j0)
            (u_b, ou), (wo_b, oo) = _flat_rows(u, u_f, j0, m, su), _flat_rows(wo, wo_f, j0, m, so)
            jp = max(j0, 0)                          # (see _flat_rows)
            if kind == GGX:                          # the warped view and the standard visible normal
                for k in range(m):
                    dev_o[k] = _deviation_at(F, wo_b, oo + 3 * k)
                    u0, u1 = u_b[ou + 2 * k], u_b[ou + 2 * k + 1]
                    r0[k] = F(_outside_unit(u0) + _outside_unit(u1))
                    cos_t, r1[k], r2[k], r6[k], r8[k] = _view_angles(F, kind, p, s1, wo_b, oo + 3 * k)
                    r3[k], r4[k], r5[k] = _ggx_visible_std(F, F(u0), F(u1), cos_t)
                for k in range(m):                   # (an integer sum in the loop above split its float32 lanes)
                    outside += 0 if r0[k] == F(0.0) else 1
            else:
                for k in range(2 * m):
                    outside += _outside_unit(u_b[ou + k])
                for k in range(m):
                    dev_o[k] = _deviation_at(F, wo_b, oo + 3 * k)
                    r0[k], r1[k], r2[k], r6[k], r8[k] = _view_angles(F, kind, p, s1, wo_b, oo + 3 * k)
                _beckmann_visible_block(u_b, ou, r0, (r3, r4, r5), (gx, gy, ok_x, ok_y), m)
            top_o = _max_bits(bits_o, m, top_o)
            for k in range(m):
                jo, ji = oo + 3 * k, 3 * (jp + k)
                ox, oy, oz = F(wo_b[jo]), F(wo_b[jo + 1]), F(wo_b[jo + 2])
                cp, sp = r1[k], r2[k]
                mx, my, mz = cp * r3[k] - sp * r4[k], sp * r3[k] + cp * r4[k], r5[k]
                hx = ax * mx - xn * mz                # slope map of Eq. 3.4 on the normal
                hy = ay * (rho * mx + s1 * my) - yn * mz
                hz = mz
                n2 = hx * hx + hy * hy + hz * hz
                inv = F(1.0) / math.sqrt(n2 if n2 > F(0.0) else F(math.inf))   # 0 at n2 = 0
                hx, hy, hz = hx * inv, hy * inv, hz * inv
                oh = ox * hx + oy * hy + oz * hz
                ix, iy, iz = F(2.0) * oh * hx - ox, F(2.0) * oh * hy - oy, F(2.0) * oh * hz - oz
                co = r6[k]
                ok = (iz > F(0.0)) & (oz > F(0.0)) & (oh > F(0.0)) & (hz > F(0.0)) & (co > F(0.0))
                r2_i, ci = _warp(p, s1, ix, iy, iz)
                e, scale = _ndf_pre(F, kind, p, s1, hx, hy, hz if hz > F(0.0) else F(1.0))
                r0[k] = oh
                area, w, c = _smith_pre(F, kind, shadowing, r8[k], co, r2_i, ci)
                scale = scale if ok else F(0.0)
                wi_b[ji], wi_b[ji + 1], wi_b[ji + 2] = ix, iy, iz
                visible = (ci > F(0.0)) | (not shadowing)                         # G > 0
                if kind == GGX:                      # no Smith loop of its own: pdf and weight here
                    pdf_out[jp + k], r2[k] = _pdf_and_ratio(F, kind, area, w, c, e, scale, visible)
                else:
                    r1[k], r2[k], r5[k], r3[k], r4[k] = area, w, c, e, scale
                    r7[k] = F(1.0) if visible else F(0.0)
            if kind != GGX:
                _smith_block_post(kind, shadowing, r1, r2, r3, r6, m)
                for k in range(m):
                    pdf_out[jp + k], r2[k] = _pdf_and_ratio(F, kind, r1[k], r2[k] if shadowing else r1[k], r5[k], r3[k],
                                                            r4[k], r7[k] > F(0.0))
            _fresnel_block(F, p.fresnel, r0, r2, weight_flat, 3 * j0, m)
        return outside, _deviation(top_o, dev_o)
    return kernel


#: Public names of the helpers that other compiled modules share (:mod:`microfacet.glints.pbrdf`):
#: the decorators of inlined helpers and of multiply-add loops, ``exp`` of a non-positive
#: argument and ``erfc`` given ``exp(-v^2)``.
inline, jit_contract, exp_neg, erfc_near = _inline, _jit_contract, _exp_neg, _erfc_near
