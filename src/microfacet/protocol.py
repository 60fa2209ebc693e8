"""The BRDF protocol's input checks and ``out=`` handling, in one public module.

Every BRDF-like object of the library (:mod:`microfacet.brdf`, the measured readers of
:mod:`microfacet.measured`, the glint BRDFs of :mod:`microfacet.glints`, the fitted and
layered models) answers ``eval``, ``eval_cos``, ``pdf`` and ``sample`` over arrays, and
checks and writes them the same way, by these functions:

* directions ``wi``/``wo`` are ``(..., 3)`` unit vectors (within :data:`UNIT_TOLERANCE` of
  ``|w|^2 = 1``; NaN/inf and zero vectors fail): :func:`directions`, or
  :func:`as_directions` then :func:`check_unit` where a compiled kernel measured the
  deviation while it read them (``check_unit(w, name, deviation)``);
* uniforms ``u`` are ``(..., 2)`` in ``[0, 1]``: :func:`uniforms`, or :func:`as_uniforms`
  then :func:`check_uniforms`;
* a bad input raises one ``ValueError`` line naming the argument (``wi``, ``u`` ...);
* ``out=`` is NumPy's: a writeable C-contiguous array of the result's shape and dtype that
  shares no memory with the inputs (:func:`output`; ``sample``: a tuple of three,
  :func:`sample_outputs`), written and returned; :func:`into` / :func:`into_sample` copy a
  result computed elsewhere into it. New outputs come from the cache of freed outputs
  (:mod:`microfacet._buffers`).

Layers: this module sits above :mod:`microfacet.kernels` (whose compiled pass measures unit
lengths, :func:`microfacet.kernels.unit_deviation`) and below every BRDF; the kernels take
outputs already checked here.

Example::

    >>> import numpy as np
    >>> w = directions([[0.0, 0.6, 0.8]], "wi")
    >>> out = output(None, (1, 3), np.float64)
    >>> directions([[0.0, 0.0, 2.0]], "wi")
    Traceback (most recent call last):
    ...
    ValueError: wi must be unit vectors (| |w|^2 - 1 | <= 1e-05; normalize them first), got [0.0, 0.0, 2.0] of length 2 at index (0,)
"""
from __future__ import annotations

import numpy as np

from . import _buffers, kernels

__all__ = ["UNIT_TOLERANCE", "as_directions", "check_unit", "directions", "as_uniforms", "check_uniforms",
           "uniforms", "pair_shape", "output", "sample_outputs", "into", "into_sample"]

#: Largest accepted ``| |w|^2 - 1 |`` of a direction (``|w|`` within about ``1 +- 5e-6``):
#: unit vectors rounded to float32 pass (their error is ~1e-7); within it ``f_r`` moves by
#: ~1e-5 relative (1 % too long changes it by 2.2 %), so directions are used as given.
UNIT_TOLERANCE = 1e-5


def as_directions(w, name: str, float32: bool = False) -> np.ndarray:
    """``w`` as float64 directions ``(..., 3)`` (float32 arrays stay float32 if ``float32``, for
    the compiled kernels, which read either); ``ValueError`` naming ``name`` if the last axis is not 3.
    Not checked for unit length: :func:`check_unit`.

    Parameters
    ----------
    w : array_like
        Directions, last axis 3.
    name : str
        Parameter name for the error message.
    float32 : bool
        Keep float32 input as float32.

    Returns
    -------
    (..., 3) ndarray
        The directions, float64 (or float32).

    Examples
    --------
    >>> as_directions([0.0, 0.0, 2.0], "wo")          # not normalized, not checked for length
    array([0., 0., 2.])
    >>> as_directions([0.0, 1.0], "wo")
    Traceback (most recent call last):
        ...
    ValueError: wo must have a last axis of size 3, got shape (2,)
    """
    w = np.asarray(w)
    if not (float32 and w.dtype == np.float32):
        w = w.astype(np.float64, copy=False)
    if w.shape[-1:] != (3,):
        raise ValueError(f"{name} must have a last axis of size 3, got shape {w.shape}")
    return w


def check_unit(w, name: str, deviation=None) -> None:
    """``ValueError`` naming ``name`` if a vector of ``w`` is not unit length within
    :data:`UNIT_TOLERANCE` (NaN, inf and zero vectors included). ``deviation``: the largest
    ``| |w|^2 - 1 |`` (or an upper bound of it) if a kernel measured it while reading ``w``, else,
    and where that fails, one compiled pass (:func:`microfacet.kernels.unit_deviation`).

    Parameters
    ----------
    w : (..., 3) ndarray
        Directions.
    name : str
        Parameter name for the error message.
    deviation : float, optional
        A kernel's bound on ``| |w|^2 - 1 |``; None: measured here.

    Examples
    --------
    >>> import numpy as np
    >>> check_unit(np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]]), "wi")      # passes: returns None
    >>> check_unit(np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.9]]), "wi")
    Traceback (most recent call last):
        ...
    ValueError: wi must be unit vectors (| |w|^2 - 1 | <= 1e-05; normalize them first), got [0.6, 0.0, 0.9] of length 1.08166538 at index (1,)
    """
    if deviation is None or not deviation <= UNIT_TOLERANCE:
        deviation = kernels.unit_deviation(w)
    if not deviation <= UNIT_TOLERANCE:
        n2 = np.sum(w * w, axis=-1)
        bad = np.argwhere(~(np.abs(n2 - 1.0) <= UNIT_TOLERANCE))[0]
        where = f" at index {tuple(bad.tolist())}" if w.ndim > 1 else ""
        raise ValueError(f"{name} must be unit vectors (| |w|^2 - 1 | <= {UNIT_TOLERANCE:g}; "
                         f"normalize them first), got {w[tuple(bad)].tolist()} of length "
                         f"{np.sqrt(n2[tuple(bad)]):.9g}{where}")


def directions(w, name: str, float32: bool = False) -> np.ndarray:
    """``w`` as unit directions ``(..., 3)``, the convention of every BRDF method:
    :func:`as_directions` and :func:`check_unit`.

    Parameters
    ----------
    w : array_like
        Directions, last axis 3, unit length.
    name : str
        Parameter name for the error message.
    float32 : bool
        Keep float32 input as float32.

    Returns
    -------
    (..., 3) ndarray
        The checked directions.

    Examples
    --------
    >>> directions([[0.6, 0.0, 0.8]], "wi")
    array([[0.6, 0. , 0.8]])
    >>> directions([0.0, 0.0, 0.0], "wo")
    Traceback (most recent call last):
        ...
    ValueError: wo must be unit vectors (| |w|^2 - 1 | <= 1e-05; normalize them first), got [0.0, 0.0, 0.0] of length 0
    """
    w = as_directions(w, name, float32)
    check_unit(w, name)
    return w


def as_uniforms(u, float32: bool = False) -> np.ndarray:
    """``u`` as float64 uniforms ``(..., 2)`` (float32 arrays stay float32 if ``float32``);
    ``ValueError`` if the last axis is not 2. Not checked for range: :func:`check_uniforms`.

    Parameters
    ----------
    u : array_like
        Uniform numbers, last axis 2.
    float32 : bool
        Keep float32 input as float32.

    Returns
    -------
    (..., 2) ndarray
        The uniforms, float64 (or float32).

    Examples
    --------
    >>> as_uniforms([0.5, 1.5])                  # not checked for range: check_uniforms
    array([0.5, 1.5])
    >>> import numpy as np
    >>> as_uniforms(np.zeros(2, np.float32), float32=True).dtype
    dtype('float32')
    """
    u = np.asarray(u)
    if not (float32 and u.dtype == np.float32):
        u = u.astype(np.float64, copy=False)
    if u.shape[-1:] != (2,):
        raise ValueError(f"u must have a last axis of size 2, got shape {u.shape}")
    return u


def check_uniforms(u, name: str = "u", outside=None) -> None:
    """``ValueError`` if a value of ``u`` lies outside ``[0, 1]`` (NaN too). ``outside``: nonzero
    if a kernel found one while reading ``u``, else two NumPy passes.

    Parameters
    ----------
    u : ndarray
        Uniform numbers.
    name : str
        Parameter name for the error message.
    outside : int or bool, optional
        A kernel's count of values outside ``[0, 1]``; None: NumPy checks ``u``.

    Examples
    --------
    >>> import numpy as np
    >>> check_uniforms(np.array([0.0, 1.0]))        # passes: returns None
    >>> check_uniforms(np.array([0.5, np.nan]))
    Traceback (most recent call last):
        ...
    ValueError: u must lie in [0, 1] (uniform random numbers), got nan (1 value(s) outside)
    """
    if outside is None:
        outside = u.size and not (np.min(u) >= 0.0 and np.max(u) <= 1.0)
    if outside:
        bad = ~((u >= 0.0) & (u <= 1.0))
        raise ValueError(f"{name} must lie in [0, 1] (uniform random numbers), got {float(u[bad][0])!r} "
                         f"({int(bad.sum())} value(s) outside)")


def uniforms(u, float32: bool = False) -> np.ndarray:
    """``u`` as uniforms ``(..., 2)`` in ``[0, 1]``: :func:`as_uniforms` and :func:`check_uniforms`.

    Parameters
    ----------
    u : array_like
        Uniform numbers, last axis 2.
    float32 : bool
        Keep float32 input as float32.

    Returns
    -------
    (..., 2) ndarray
        The checked uniforms.

    Examples
    --------
    >>> uniforms([[0.1, 0.9]])
    array([[0.1, 0.9]])
    >>> uniforms([0.1, 0.2, 0.3])
    Traceback (most recent call last):
        ...
    ValueError: u must have a last axis of size 2, got shape (3,)
    """
    u = as_uniforms(u, float32)
    check_uniforms(u)
    return u


def pair_shape(a, b) -> tuple:
    """The batch shape of two inputs ``(..., k)`` (their leading axes broadcast); ``ValueError``
    if they do not broadcast.

    Parameters
    ----------
    a, b : ndarray
        Inputs ``(..., k)``.

    Returns
    -------
    tuple of int
        The broadcast leading shape.

    Examples
    --------
    >>> import numpy as np
    >>> pair_shape(np.zeros((4, 1, 3)), np.zeros((5, 3)))
    (4, 5)
    >>> pair_shape(np.zeros((4, 3)), np.zeros((5, 3)))
    Traceback (most recent call last):
        ...
    ValueError: shape mismatch: ...Mismatch is between arg 0 with shape (4,) and arg 1 with shape (5,).
    """
    return a.shape[:-1] if a.shape[:-1] == b.shape[:-1] else np.broadcast_shapes(a.shape[:-1], b.shape[:-1])


def output(out, shape, dtype, name="out", inputs=()):
    """``out`` (an output array a caller passes to be written, as NumPy's ``out=``), or a new
    array if it is ``None``: ``ValueError`` naming ``name`` unless it is a writeable
    C-contiguous ndarray of ``shape`` and ``dtype`` that shares no memory with ``inputs``. New
    arrays come from the cache of freed outputs (:mod:`microfacet._buffers`,
    :func:`microfacet.kernels.release_outputs`).

    Parameters
    ----------
    out : ndarray or None
        The caller's output array, or None for a new one.
    shape : tuple of int
        Required shape.
    dtype : dtype
        Required dtype.
    name : str
        Parameter name for the error message.
    inputs : tuple of ndarray
        Arrays ``out`` must not share memory with.

    Returns
    -------
    ndarray
        ``out`` or a new (uninitialized) array.

    Examples
    --------
    >>> import numpy as np
    >>> output(None, (2, 3), np.float64).shape           # a new array
    (2, 3)
    >>> out = np.empty((2, 3))
    >>> output(out, (2, 3), np.float64) is out
    True
    >>> output(np.empty((2, 3), np.float32), (2, 3), np.float64)
    Traceback (most recent call last):
        ...
    ValueError: out must be a writeable C-contiguous float64 array of shape (2, 3), got float32 array of shape (2, 3)
    """
    if out is None:
        return _buffers.empty(shape, dtype)
    if not (isinstance(out, np.ndarray) and out.shape == shape and out.dtype == dtype
            and out.flags.c_contiguous and out.flags.writeable):
        got = (("read-only " if not out.flags.writeable else "") + ("non-contiguous " if not out.flags.c_contiguous else "")
               + f"{out.dtype} array of shape {out.shape}") if isinstance(out, np.ndarray) else type(out).__name__
        raise ValueError(f"{name} must be a writeable C-contiguous {np.dtype(dtype)} array of shape {shape}, got {got}")
    if any(np.may_share_memory(out, a) for a in inputs):
        raise ValueError(f"{name} must not share memory with the inputs")
    return out


def sample_outputs(out, shape, dtype, inputs=()):
    """``(wi, weight, pdf)`` of a sample of ``shape``: ``out``'s three arrays (:func:`output`,
    named ``out[0]`` ... ``out[2]``, distinct), or new ones if it is ``None``.

    Parameters
    ----------
    out : tuple of 3 ndarray or None
        The caller's ``(wi, weight, pdf)`` arrays, or None for new ones.
    shape : tuple of int
        Batch shape (``wi`` and ``weight`` get a last axis of 3).
    dtype : dtype
        Required dtype.
    inputs : tuple of ndarray
        Arrays ``out`` must not share memory with.

    Returns
    -------
    tuple of 3 ndarray
        ``(wi, weight, pdf)``.

    Examples
    --------
    >>> import numpy as np
    >>> [a.shape for a in sample_outputs(None, (4,), np.float64)]
    [(4, 3), (4, 3), (4,)]
    >>> sample_outputs(np.empty((4, 3)), (4,), np.float64)
    Traceback (most recent call last):
        ...
    ValueError: out must be a tuple of three arrays (wi, weight, pdf), got ndarray
    """
    if out is None:
        out = (None,) * 3
    elif not (isinstance(out, tuple) and len(out) == 3):
        raise ValueError(f"out must be a tuple of three arrays (wi, weight, pdf), got {type(out).__name__}")
    arrays = [output(o, shape + last, dtype, f"out[{j}]", inputs)
              for j, (o, last) in enumerate(zip(out, ((3,), (3,), ())))]
    if any(np.may_share_memory(a, b) for j, a in enumerate(arrays) for b in arrays[j + 1:]):
        raise ValueError("out's three arrays must not share memory")
    return tuple(arrays)


def into(out, result: np.ndarray, inputs) -> np.ndarray:
    """``result``, or ``out`` with ``result`` copied in (checked by :func:`output`).

    Parameters
    ----------
    out : ndarray or None
        The caller's output array, or None.
    result : ndarray
        The computed values.
    inputs : tuple of ndarray
        Arrays ``out`` must not overlap.

    Returns
    -------
    ndarray
        ``out`` (filled) or ``result``.

    Examples
    --------
    >>> import numpy as np
    >>> into(None, np.ones(2), ())
    array([1., 1.])
    >>> out = np.zeros(2)
    >>> into(out, np.ones(2), ()) is out, out
    (True, array([1., 1.]))
    """
    if out is None:
        return result
    np.copyto(output(out, result.shape, result.dtype, "out", tuple(inputs)), result)
    return out


def into_sample(out, result, inputs):
    """``(wi, weight, pdf)`` ``result``, or ``out``'s three arrays with it copied in
    (checked by :func:`sample_outputs`).

    Parameters
    ----------
    out : tuple of 3 ndarray or None
        The caller's ``(wi, weight, pdf)`` arrays, or None.
    result : tuple of 3 ndarray
        The computed ``(wi, weight, pdf)``.
    inputs : tuple of ndarray
        Arrays ``out`` must not overlap.

    Returns
    -------
    tuple of 3 ndarray
        ``out`` (filled) or ``result``.

    Examples
    --------
    >>> import numpy as np
    >>> result = (np.zeros((1, 3)), np.ones((1, 3)), np.ones(1))
    >>> into_sample(None, result, ()) is result
    True
    >>> out = (np.empty((1, 3)), np.empty((1, 3)), np.empty(1))
    >>> into_sample(out, result, ())[2]
    array([1.])
    """
    if out is None:
        return result
    out = sample_outputs(out, result[2].shape, result[2].dtype, tuple(inputs))
    for o, a in zip(out, result):
        np.copyto(o, a)
    return out
