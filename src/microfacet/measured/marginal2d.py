"""Vectorized ``Marginal2D`` (continuous variant): bilinear tables on ``[0, 1]^2`` that
depend multilinearly on extra parameters, with the inverse of their sample warp.

This is the interpolant and warp of Mitsuba 3 (``include/mitsuba/core/distr_2d.h``,
``Marginal2D<Float, Dim, Continuous=true>``) and of rgl-epfl/brdf-loader, written anew in
NumPy float64 for the RGL reader. A table of resolution ``W x H`` (columns x rows) covers
``[0, 1]^2`` with ``(W - 1) x (H - 1)`` bilinear patches; ``pos = (x, y)`` indexes columns
with ``x`` and rows with ``y``. The density is sampled by inverting the marginal CDF of
``y`` then the conditional CDF of ``x``, both integrals of the bilinear interpolant.
"""
from __future__ import annotations

import numpy as np

__all__ = ["Marginal2D"]


def _lerp(a, b, t):
    return a + (b - a) * t


class Marginal2D:
    """Bilinear 2D table, multilinear in parameters, with CDFs for the inverse warp.

    Parameters
    ----------
    data : ndarray, (*param_sizes, H, W) or (*param_sizes, H, W, K)
        Table values; an optional trailing axis of ``K`` channels is interpolated alike.
    param_values : sequence of 1-D arrays
        Increasing node positions of each parameter (``len == param_sizes[d]``).
    normalize : bool
        Scale each slice to integrate to 1 over ``[0, 1]^2`` (so ``eval`` is a density).
    invertible : bool
        Build the conditional and marginal CDFs needed by :meth:`invert` (scalar tables).

    Examples
    --------
    >>> import numpy as np
    >>> table = Marginal2D(np.array([[1.0, 1.0], [3.0, 3.0]]), normalize=True, invertible=True)
    >>> table.eval(np.array([0.0, 0.5, 1.0]), np.array([0.5, 0.5, 0.5]))     # a density on [0, 1]^2
    array([1., 1., 1.])
    >>> table.invert(np.array([0.5]), np.array([0.5]))     # the warped point and its density
    (array([0.5]), array([0.375]), array([1.]))
    """

    def __init__(self, data, param_values=(), normalize: bool = False, invertible: bool = False):
        data = np.asarray(data, dtype=np.float64)
        self.params = [np.asarray(p, dtype=np.float64) for p in param_values]
        n_par = len(self.params)
        self.channels = data.ndim > n_par + 2
        self.H, self.W = data.shape[n_par:n_par + 2]
        self.param_sizes = data.shape[:n_par]
        self.data = data.reshape((-1, self.H, self.W, data.shape[-1] if self.channels else 1))
        self.normalized = normalize
        if invertible:
            self._build_cdfs()
        elif normalize:
            cells = self.data[:, :-1, :-1] + self.data[:, 1:, :-1] + self.data[:, :-1, 1:] + self.data[:, 1:, 1:]
            self.data = self.data / (cells.sum(axis=(1, 2), keepdims=True) / (4 * (self.W - 1) * (self.H - 1)))

    def _build_cdfs(self):
        """Trapezoid CDFs: ``cond[s, y, x]`` = integral of row ``y`` over ``[0, x/(W-1)]``,
        ``marg[s, y]`` = integral of the row integrals over ``[0, y/(H-1)]`` (leading 0s)."""
        d = self.data[..., 0]
        cond = np.cumsum(0.5 / (self.W - 1) * (d[..., :-1] + d[..., 1:]), axis=-1)
        row = cond[..., -1]
        marg = np.cumsum(0.5 / (self.H - 1) * (row[..., :-1] + row[..., 1:]), axis=-1)
        norm = 1.0 / marg[..., -1] if self.normalized else np.ones(len(d))
        pad = lambda a: np.concatenate([np.zeros(a.shape[:-1] + (1,)), a], axis=-1)  # noqa: E731
        self.cond = pad(cond) * norm[:, None, None]
        self.marg = pad(marg) * norm[:, None]
        self.data = self.data * norm[:, None, None, None]

    # ------------------------------------------------------------- parameters
    def _slices(self, param):
        """Slice indices and multilinear weights of the ``2^D`` parameter corners, each
        ``(2^D, ...)``: the node interval is the last node below ``p`` (``find_interval``),
        its weight ``clip((p - p0) / (p1 - p0), 0, 1)``; one-node parameters weigh 1."""
        shape = np.broadcast_shapes(*(np.shape(p) for p in param)) if param else ()
        slices, weights = np.zeros((1,) + shape, dtype=np.intp), np.ones((1,) + shape)
        for nodes, p in zip(self.params, param):
            p = np.asarray(p, dtype=np.float64)
            n = len(nodes)
            if n == 1:
                i0, t = np.zeros(shape, dtype=np.intp), np.zeros(shape)
            else:
                i0 = np.clip(np.searchsorted(nodes, p, side="left") - 1, 0, n - 2)
                t = np.clip((p - nodes[i0]) / (nodes[np.minimum(i0 + 1, n - 1)] - nodes[i0]), 0.0, 1.0)
            i1 = np.minimum(i0 + 1, n - 1)
            slices = np.concatenate([slices * n + i0, slices * n + i1])
            weights = np.concatenate([weights * (1.0 - t), weights * t])
        return slices, weights

    def _lookup(self, table, index, corners):
        """Multilinear blend over the parameter corners of ``table[slice, *index]``."""
        slices, weights = corners
        v = table[tuple(np.broadcast_arrays(slices, *(np.asarray(i)[None] for i in index)))]
        w = weights if v.ndim == weights.ndim else weights[..., None]
        return (w * v).sum(axis=0)

    @staticmethod
    def _cell(u, n: int):
        """Patch index ``min(floor(u (n-1)), n-2)`` and local coordinate of ``u`` in [0, 1]."""
        s = np.clip(np.nan_to_num(u), 0.0, 1.0) * (n - 1)
        i = np.minimum(s.astype(np.intp), n - 2)
        return i, s - i

    # ------------------------------------------------------------------ public
    def eval(self, x, y, param=()) -> np.ndarray:
        """Bilinear value at ``(x, y)`` in ``[0, 1]^2`` (clamped), ``(...)`` or ``(..., K)``.

        Parameters
        ----------
        x, y : array_like
            Coordinates in ``[0, 1]`` (columns, rows).
        param : sequence of array_like
            Values of the table's parameters (one per parameter axis).

        Returns
        -------
        ndarray
            ``(...)``, or ``(..., K)`` for a table with channels.
        """
        c = self._slices(param)
        (i, fx), (j, fy) = self._cell(x, self.W), self._cell(y, self.H)
        fx, fy = fx[..., None], fy[..., None]             # the data's channel axis
        v00, v10 = self._lookup(self.data, (j, i), c), self._lookup(self.data, (j, i + 1), c)
        v01, v11 = self._lookup(self.data, (j + 1, i), c), self._lookup(self.data, (j + 1, i + 1), c)
        out = _lerp(_lerp(v00, v10, fx), _lerp(v01, v11, fx), fy)
        return out if self.channels else out[..., 0]

    def invert(self, x, y, param=()):
        """Inverse of the sample warp: the uniforms ``(u1, u2)`` that warp to ``(x, y)``,
        and the density there. ``u2`` inverts the marginal CDF of rows, ``u1`` the
        conditional CDF of columns, each integral of the bilinear patch (segment
        ``t (v0 + (v1 - v0) t / 2) / (n - 1)``).

        Parameters
        ----------
        x, y : array_like
            Coordinates in ``[0, 1]``.
        param : sequence of array_like
            Values of the table's parameters.

        Returns
        -------
        u1, u2 : ndarray
            The uniforms.
        pdf : ndarray
            The density at ``(x, y)``.
        """
        c = self._slices(param)
        (i, fx), (j, fy) = self._cell(x, self.W), self._cell(y, self.H)
        look = lambda t, *idx: self._lookup(t, idx, c)  # noqa: E731
        d = self.data
        c0 = _lerp(look(d, j, i, 0), look(d, j + 1, i, 0), fy)
        c1 = _lerp(look(d, j, i + 1, 0), look(d, j + 1, i + 1, 0), fy)
        pdf = _lerp(c0, c1, fx)
        u1 = fx * _lerp(c0, c1, 0.5 * fx) / (self.W - 1)
        u1 = u1 + _lerp(look(self.cond, j, i), look(self.cond, j + 1, i), fy)
        r0, r1 = look(self.cond, j, self.W - 1), look(self.cond, j + 1, self.W - 1)
        u1 = u1 / _lerp(r0, r1, fy)
        u2 = fy * _lerp(r0, r1, 0.5 * fy) / (self.H - 1) + look(self.marg, j)
        if not self.normalized:
            u2 = u2 / look(self.marg, self.H - 1)
        return u1, u2, pdf
