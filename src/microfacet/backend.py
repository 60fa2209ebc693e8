"""The one choice between the NumPy reference and the compiled (Numba) backend.

Every fast path of the library has two implementations of the same equations: the NumPy
reference (:mod:`microfacet.distributions`, :mod:`microfacet.brdf`, the readers of
:mod:`microfacet.measured`, :mod:`microfacet.glints`) and a compiled one (Numba kernels:
:mod:`microfacet.kernels` and the modules' own loops), tested against it
(``tests/test_backend_drift.py``, ``tests/test_kernels.py``). Which one runs is decided here,
and only here, by :func:`choose`:

* ``"numba"`` where the compiled backend is available (:func:`available`: Numba installed,
  not disabled by ``MICROFACET_NUMBA=0``, :data:`microfacet.kernels.AVAILABLE` read at each
  call, so that a process may switch it off, as ``microfacet fit`` and the benchmarks do) and
  the caller has compiled code for the case;
* ``"numpy"`` otherwise, or when asked (a ``backend="numpy"`` argument).

Callers: :class:`microfacet.MicrofacetBRDF` (:func:`smith`: whether its fused Smith kernels
run), the measured readers (:func:`microfacet.measured.base.compiled_kernels`), the glints
P-BRDF, image kernel and naive renderer (their ``backend`` arguments). While a kernel compiles
in the background, a call may still run the NumPy reference (:mod:`microfacet.kernels`,
``MICROFACET_COMPILE``): that is a matter of when, not of which backend.

Example::

    >>> BACKENDS, AUTO
    (('auto', 'numpy', 'numba'), 'auto')
    >>> choose("numpy")
    'numpy'
    >>> choose("cuda")
    Traceback (most recent call last):
    ...
    ValueError: backend must be 'auto', 'numpy' or 'numba', got 'cuda'
"""
from __future__ import annotations

from . import kernels

__all__ = ["AUTO", "NUMPY", "NUMBA", "BACKENDS", "available", "choose", "smith"]

#: The backend requests: the choice left to :func:`choose`, the NumPy reference, the compiled kernels.
AUTO = "auto"
NUMPY = "numpy"
NUMBA = "numba"
#: The accepted ``backend`` arguments.
BACKENDS = (AUTO, NUMPY, NUMBA)


def available() -> bool:
    """Whether the compiled backend may run now: :data:`microfacet.kernels.AVAILABLE` (Numba
    installed and ``MICROFACET_NUMBA`` not ``0``; a process may set it to False).

    Returns
    -------
    bool
        True where the compiled backend may run.

    Examples
    --------
    >>> from microfacet import kernels
    >>> available() == kernels.AVAILABLE          # True where Numba is installed
    True
    """
    return kernels.AVAILABLE


def choose(requested: str = AUTO, compiled: bool = True, name: str = "backend") -> str:
    """The backend that runs for a request ``requested`` (:data:`BACKENDS`): :data:`NUMBA` for
    ``"auto"`` or ``"numba"`` when :func:`available` and the caller has ``compiled`` code for the
    case, else :data:`NUMPY`. ``ValueError`` naming ``name`` for an unknown request, or for
    ``"numba"`` where it cannot run. Example: ``choose()`` is ``"numba"`` with Numba installed.

    Parameters
    ----------
    requested : str
        ``"auto"``, ``"numba"`` or ``"numpy"``.
    compiled : bool
        Whether the caller has compiled code for the case.
    name : str
        Parameter name for the error message.

    Returns
    -------
    str
        :data:`NUMBA` or :data:`NUMPY`.

    Examples
    --------
    >>> choose("numpy"), NUMPY
    ('numpy', 'numpy')
    >>> choose("auto") == (NUMBA if available() else NUMPY)
    True
    >>> choose("auto", compiled=False)            # the caller has no compiled code for the case
    'numpy'
    >>> choose("gpu", name="glints backend")
    Traceback (most recent call last):
        ...
    ValueError: glints backend must be 'auto', 'numpy' or 'numba', got 'gpu'
    """
    if requested not in BACKENDS:
        raise ValueError(f"{name} must be 'auto', 'numpy' or 'numba', got {requested!r}")
    runs = bool(compiled) and available()
    if requested == NUMBA and not runs:
        raise ValueError(f"{name} 'numba' is not available (numba missing or MICROFACET_NUMBA=0)")
    return NUMBA if requested != NUMPY and runs else NUMPY


def smith(brdf) -> bool:
    """Whether the compiled Smith kernels (:func:`microfacet.kernels.smith_eval`, ``smith_pdf``,
    ``smith_sample``) run for the :class:`~microfacet.MicrofacetBRDF` ``brdf``: the compiled
    backend is chosen (:func:`choose`) and the BRDF has a kernel record (``brdf.params``: Smith
    GAF, scalar Beckmann or GGX, a Fresnel term with a record). Example: ``smith(mf.MicrofacetBRDF(mf.GGX(0.3)))``.

    Parameters
    ----------
    brdf : MicrofacetBRDF
        The BRDF.

    Returns
    -------
    bool
        True where the compiled kernels run for it.

    Examples
    --------
    >>> import microfacet as mf
    >>> smith(mf.MicrofacetBRDF(mf.GGX(alpha=0.3))) == available()
    True
    >>> smith(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), gaf="vgroove"))     # no kernel for V-grooves
    False
    """
    return choose(AUTO, getattr(brdf, "params", None) is not None) == NUMBA
