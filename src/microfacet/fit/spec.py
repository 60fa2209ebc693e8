"""Analytic fits as plain data: a BRDF tree to a JSON-able dict and back.

A fit file (``microfacet fit``'s ``OUT.npz``) stores each analytic fit as the spec of
:func:`to_spec`, a nested dict that names the math:

* ``{"type": "microfacet", "distribution": {"type": "ggx"|"beckmann", "alpha_x",
  "alpha_y", "rho", "mean_slope"}, "fresnel": FRESNEL, "gaf", "shadowing"}`` — a
  :class:`microfacet.MicrofacetBRDF` (Eq. 2.1);
* ``{"type": "lambertian", "reflectance": [r, g, b]}``;
* ``{"type": "transmitted_lambertian", "reflectance": [r, g, b], "eta": eta}`` (:class:`microfacet.diffuse.TransmittedLambertian`);
* ``{"type": "sum", "parts": [...], "weights": [...]}`` — :class:`microfacet.fit.SumBRDF`;
* ``{"type": "layered", "coat": MICROFACET, "base": SPEC}`` —
  :class:`microfacet.layered.LayeredBRDF`;

and ``FRESNEL`` one of ``{"type": "schlick", "f0", "f90"}``, ``{"type": "f82tint",
"f0", "f82"}``, ``{"type": "conductor", "eta", "k"}``, ``{"type": "dielectric",
"eta"}``, ``{"type": "tabulated", "cos_theta_d", "rgb"}``, ``{"type": "ideal"}``.
:func:`from_spec` rebuilds the BRDF exactly (float64 values as written).

Examples
--------
>>> import microfacet as mf
>>> from microfacet.fit.spec import from_spec, to_spec
>>> b = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), fresnel=mf.fresnel.Schlick(0.04))
>>> to_spec(b)["distribution"]["alpha_x"]
0.2
>>> float(from_spec(to_spec(b)).distribution.alpha_x)
0.2
"""
from __future__ import annotations

import numpy as np

__all__ = ["to_spec", "from_spec", "fresnel_spec", "fresnel_from_spec"]


def _list(v) -> list | float:
    return np.asarray(v, dtype=np.float64).tolist()


def fresnel_spec(fresnel) -> dict:
    """The spec of a Fresnel term of :mod:`microfacet.fresnel`.

    Parameters
    ----------
    fresnel : microfacet.fresnel.Fresnel
        A Schlick, F82-tint, conductor, dielectric, tabulated or ideal term.

    Returns
    -------
    dict
        Its spec (module docstring).

    Examples
    --------
    >>> import microfacet as mf
    >>> fresnel_spec(mf.fresnel.Schlick(0.04))
    {'type': 'schlick', 'f0': [0.04, 0.04, 0.04], 'f90': [1.0, 1.0, 1.0]}
    >>> fresnel_spec(mf.fresnel.Dielectric(eta=1.5))
    {'type': 'dielectric', 'eta': [1.5, 1.5, 1.5]}
    """
    from .. import fresnel as fr
    if isinstance(fresnel, fr.Schlick):
        return {"type": "schlick", "f0": _list(fresnel.f0), "f90": _list(getattr(fresnel, "f90", 1.0))}
    if isinstance(fresnel, fr.F82Tint):
        return {"type": "f82tint", "f0": _list(fresnel.f0), "f82": _list(fresnel.f82)}
    if isinstance(fresnel, fr.Conductor):
        return {"type": "conductor", "eta": _list(fresnel.eta), "k": _list(fresnel.k)}
    if isinstance(fresnel, fr.Dielectric):
        return {"type": "dielectric", "eta": _list(fresnel.eta)}
    if isinstance(fresnel, fr.Tabulated):
        return {"type": "tabulated", "cos_theta_d": _list(fresnel.cos_theta_d), "rgb": _list(fresnel.values)}
    if isinstance(fresnel, fr.Ideal):
        return {"type": "ideal"}
    raise ValueError(f"no spec for the Fresnel term {type(fresnel).__name__}")


def fresnel_from_spec(spec: dict):
    """The Fresnel term of a :func:`fresnel_spec`.

    Parameters
    ----------
    spec : dict
        A :func:`fresnel_spec`.

    Returns
    -------
    microfacet.fresnel.Fresnel
        The Fresnel term.

    Examples
    --------
    >>> fresnel_from_spec({"type": "dielectric", "eta": 1.5})
    Dielectric(eta=[1.5, 1.5, 1.5])
    >>> fresnel_from_spec({"type": "ideal"})
    Ideal()
    """
    from .. import fresnel as fr
    kinds = {"schlick": lambda s: fr.Schlick(s["f0"], s.get("f90", 1.0)),
             "f82tint": lambda s: fr.F82Tint(s["f0"], s["f82"]),
             "conductor": lambda s: fr.Conductor(s["eta"], s["k"]),
             "dielectric": lambda s: fr.Dielectric(s["eta"]),
             "tabulated": lambda s: fr.Tabulated(s["cos_theta_d"], s["rgb"]),
             "ideal": lambda s: fr.Ideal()}
    kind = spec.get("type")
    if kind not in kinds:
        raise ValueError(f"unknown Fresnel type {kind!r} (known: {sorted(kinds)})")
    return kinds[kind](spec)


def to_spec(brdf) -> dict:
    """The spec (module docstring) of an analytic BRDF tree.

    Parameters
    ----------
    brdf : BRDF
        An analytic tree: microfacet lobes (GGX, Beckmann), Lambertian terms, sums, layers.

    Returns
    -------
    dict
        Its spec.

    Examples
    --------
    >>> import microfacet as mf
    >>> to_spec(mf.Lambertian(0.5))
    {'type': 'lambertian', 'reflectance': [0.5, 0.5, 0.5]}
    >>> spec = to_spec(mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.2)), mf.Lambertian(0.1)))
    >>> spec["type"], [part["type"] for part in spec["parts"]]
    ('sum', ['microfacet', 'lambertian'])
    """
    from ..brdf import Lambertian, MicrofacetBRDF
    from ..diffuse import TransmittedLambertian
    from ..distributions import GGX, Beckmann
    from .analytic import SumBRDF
    if isinstance(brdf, MicrofacetBRDF):
        d = brdf.distribution
        if not isinstance(d, (GGX, Beckmann)):
            raise ValueError(f"no spec for the distribution {type(d).__name__} (analytic GGX or Beckmann only)")
        return {"type": "microfacet",
                "distribution": {"type": type(d).__name__.lower(), "alpha_x": float(d.alpha_x),
                                 "alpha_y": float(d.alpha_y), "rho": float(d.rho),
                                 "mean_slope": _list(d.mean_slope)},
                "fresnel": fresnel_spec(brdf.fresnel), "gaf": brdf.gaf_model, "shadowing": bool(brdf.shadowing)}
    if isinstance(brdf, Lambertian):
        return {"type": "lambertian", "reflectance": _list(brdf.reflectance)}
    if isinstance(brdf, TransmittedLambertian):
        return {"type": "transmitted_lambertian", "reflectance": _list(brdf.reflectance), "eta": brdf.eta}
    if isinstance(brdf, SumBRDF):
        return {"type": "sum", "parts": [to_spec(b) for b in brdf.brdfs], "weights": _list(brdf.weights)}
    if type(brdf).__name__ == "LayeredBRDF":      # microfacet.layered, not imported for the others (SciPy)
        return {"type": "layered", "coat": to_spec(brdf.coat), "base": to_spec(brdf.base)}
    raise ValueError(f"no spec for {type(brdf).__name__}")


def from_spec(spec: dict):
    """The BRDF of a :func:`to_spec` spec; ``ValueError`` naming what is wrong.

    Parameters
    ----------
    spec : dict
        A :func:`to_spec` spec.

    Returns
    -------
    BRDF
        The BRDF tree.

    Examples
    --------
    >>> from_spec({"type": "lambertian", "reflectance": [0.5, 0.4, 0.3]})
    Lambertian(reflectance=[0.5, 0.4, 0.3])
    >>> from_spec({"type": "phong"})
    Traceback (most recent call last):
        ...
    ValueError: unknown BRDF spec type 'phong' (known: microfacet, lambertian, transmitted_lambertian, sum, layered)
    """
    from ..brdf import Lambertian, MicrofacetBRDF
    from ..diffuse import TransmittedLambertian
    from ..distributions import GGX, Beckmann
    from .analytic import SumBRDF
    kind = spec.get("type") if isinstance(spec, dict) else None
    if kind == "microfacet":
        d = spec["distribution"]
        family = {"ggx": GGX, "beckmann": Beckmann}.get(d.get("type"))
        if family is None:
            raise ValueError(f"unknown distribution type {d.get('type')!r}")
        dist = family(alpha_x=d["alpha_x"], alpha_y=d["alpha_y"], rho=d.get("rho", 0.0),
                      mean_slope=d.get("mean_slope", (0.0, 0.0)))
        return MicrofacetBRDF(dist, fresnel=fresnel_from_spec(spec["fresnel"]), gaf=spec.get("gaf", "smith"),
                              shadowing=spec.get("shadowing", True))
    if kind == "lambertian":
        return Lambertian(spec["reflectance"])
    if kind == "transmitted_lambertian":
        return TransmittedLambertian(spec["reflectance"], spec.get("eta", 1.5))
    if kind == "sum":
        return SumBRDF(*(from_spec(p) for p in spec["parts"]), weights=spec.get("weights"))
    if kind == "layered":
        from ..layered import LayeredBRDF
        return LayeredBRDF(from_spec(spec["coat"]), from_spec(spec["base"]))
    raise ValueError(f"unknown BRDF spec type {kind!r} (known: microfacet, lambertian, transmitted_lambertian, sum, layered)")
