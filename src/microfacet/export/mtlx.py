"""MaterialX 1.39 documents of library BRDFs: an exact pbrlib graph and an OpenPBR surface.

* ``pbrlib`` graph (exact, up to what pbrlib lacks): each GGX lobe is a BSDF node with
  ``roughness = (alpha1, alpha2)`` (pbrlib's roughness *is* alpha) and ``tangent`` the
  geometry tangent turned by ``phi`` about the normal (``rotate3d`` by ``-phi`` degrees:
  MaterialX turns the other way); Schlick ``(f0, f90)`` is ``generalized_schlick_bsdf``
  (``color0, color90``, exponent 5), F82 tint its ``color82``, a conductor
  ``conductor_bsdf`` (``ior = eta``, ``extinction = k``), a dielectric ``dielectric_bsdf``
  (``scatter_mode R``), a Fresnel table its least-squares Schlick; a Lambertian base
  ``oren_nayar_diffuse_bsdf`` with roughness 0; sums ``add``; a coat ``layer(top=coat,
  base)``. Lost: Beckmann (pbrlib is GGX only), mean slopes, and the anisotropic Smith
  term (MaterialX shadows with ``sqrt(alpha_x alpha_y)``).
* ``open_pbr_surface`` (Andersson et al. 2024): ``specular_roughness r`` and
  ``specular_roughness_anisotropy a`` with ``alpha_t = r^2 sqrt(2 / (1 + (1 - a)^2))``,
  ``alpha_b = (1 - a) alpha_t``, i.e. ``a = 1 - alpha2/alpha1``,
  ``r = sqrt(alpha1 / sqrt(2 / (1 + (1 - a)^2)))``; a metal lobe is ``base_metalness 1``,
  ``base_color = F(0)``, ``specular_color = f82`` (F82 tint; for Schlick ``(f0, f90)``
  the tint through ``F(82 deg)``); a lobe over a Lambertian base is the dielectric with
  ``specular_ior`` from ``f0`` and ``base_color`` the base; a coat ``coat_weight 1``.

Examples
--------
>>> import microfacet as mf
>>> doc, lost = mtlx_document(mf.MicrofacetBRDF(mf.GGX(alpha=0.1)))
>>> validate(doc)
[]
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .analysis import analyse, schlick_of

__all__ = ["mtlx_document", "openpbr_inputs", "openpbr_brdf", "pbrlib_brdf", "validate", "write_mtlx",
           "glsl_source", "F82_COS"]

#: Cosine where OpenPBR's F82 tint applies (``1/7``, ~81.8 deg).
F82_COS = 1.0 / 7.0


def _mx():
    try:
        import MaterialX as mx
    except ImportError as e:                      # pragma: no cover - the extra is absent
        raise ImportError("MaterialX export needs the 'materialx' package: pip install 'microfacet[export]'") from e
    return mx


def _color(mx, rgb):
    return mx.Color3(*(float(v) for v in np.asarray(rgb, float).reshape(3)))


def _tangent(mx, graph, phi: float, name: str):
    """A ``rotate3d`` node turning the geometry tangent by ``phi`` about the normal."""
    t = graph.addNode("tangent", name + "_t", "vector3")
    t.setInputValue("space", "world")
    n = graph.addNode("normal", name + "_n", "vector3")
    n.setInputValue("space", "world")
    r = graph.addNode("rotate3d", name + "_rot", "vector3")
    r.setConnectedNode("in", t)
    r.setConnectedNode("axis", n)
    r.setInputValue("amount", float(-math.degrees(phi)))
    return r


def _lobe_node(mx, graph, lobe, name: str, lost: list):
    from .. import fresnel as fr
    f = lobe.fresnel
    if isinstance(f, fr.Conductor):
        node = graph.addNode("conductor_bsdf", name, "BSDF")
        node.setInputValue("ior", _color(mx, f.eta))
        node.setInputValue("extinction", _color(mx, f.k))
    elif isinstance(f, fr.Dielectric):
        node = graph.addNode("dielectric_bsdf", name, "BSDF")
        node.setInputValue("ior", float(np.mean(f.eta)))
        node.setInputValue("scatter_mode", "R")
        if np.ptp(f.eta) > 1e-6:
            lost.append(f"{name}: RGB dielectric index exported as its mean")
    else:
        node = graph.addNode("generalized_schlick_bsdf", name, "BSDF")
        if isinstance(f, fr.F82Tint):
            f0, f90, f82 = f.f0, np.ones(3), f.f82
        else:
            f0, f90 = schlick_of(f)
            f82 = np.ones(3)
            if isinstance(f, fr.Tabulated):
                lost.append(f"{name}: Fresnel table exported as its least-squares Schlick")
        node.setInputValue("color0", _color(mx, f0))
        node.setInputValue("color82", _color(mx, f82))
        node.setInputValue("color90", _color(mx, f90))
        node.setInputValue("exponent", 5.0)
        node.setInputValue("scatter_mode", "R")
    node.setInputValue("roughness", mx.Vector2(float(lobe.alpha1), float(lobe.alpha2)))
    if not lobe.isotropic:
        node.setConnectedNode("tangent", _tangent(mx, graph, lobe.phi, name))
        lost.append(f"{name}: MaterialX's anisotropic Smith term uses sqrt(alpha1 alpha2) (the library's the "
                    "ellipse's projected roughness)")
    if lobe.family != "ggx":
        lost.append(f"{name}: Beckmann lobe exported as GGX (pbrlib has GGX only)")
    if max(abs(v) for v in lobe.mean_slope) > 1e-6:
        lost.append(f"{name}: mean slope dropped")
    return node


def _pbrlib(mx, doc, a, lost: list):
    graph = doc.addNodeGraph("NG_microfacet")
    nodes = [_lobe_node(mx, graph, lobe, f"lobe{i}", lost) for i, lobe in enumerate(a.lobes)]
    if a.base is not None:
        d = graph.addNode("oren_nayar_diffuse_bsdf", "base", "BSDF")
        d.setInputValue("color", _color(mx, a.base))
        d.setInputValue("roughness", 0.0)
        nodes.append(d)
    top = nodes[0]
    for k, other in enumerate(nodes[1:]):
        add = graph.addNode("add", f"sum{k}", "BSDF")
        add.setConnectedNode("in1", top)
        add.setConnectedNode("in2", other)
        top = add
    if a.coat is not None:
        coat = _lobe_node(mx, graph, a.coat, "coat", lost)
        layer = graph.addNode("layer", "coated", "BSDF")
        layer.setConnectedNode("top", coat)
        layer.setConnectedNode("base", top)
        top = layer
        lost.append("coat: MaterialX's layer attenuates the base by the coat's view-side transmission "
                    "1 - E_c(theta_o) only (the library's LayeredBRDF by both sides')")
    out = graph.addOutput("out", "BSDF")
    out.setConnectedNode(top)
    surf = doc.addNode("surface", "SR_microfacet_exact", "surfaceshader")
    surf.setConnectedOutput("bsdf", out)
    mat = doc.addMaterialNode("M_microfacet_exact", surf)
    return mat


def openpbr_inputs(brdf) -> tuple[dict, list[str]]:
    """``(inputs, lost)``: the ``open_pbr_surface`` inputs (name -> float or RGB list) of a
    library BRDF tree (module docstring) and what they could not carry.

    Parameters
    ----------
    brdf : BRDF
        An analytic BRDF tree (:func:`~microfacet.export.analysis.analyse`).

    Returns
    -------
    inputs : dict
        ``open_pbr_surface`` input name -> float or RGB list (plus ``tangent_rotation``,
        radians, for an anisotropic lobe: written as a rotated ``geometry_tangent``).
    lost : list of str
        What OpenPBR could not hold.

    Examples
    --------
    A Schlick metal: OpenPBR's F82 tint through ``F(82 deg)`` (:data:`F82_COS`):

    >>> import math, microfacet as mf
    >>> round(math.degrees(math.acos(F82_COS)), 1)
    81.8
    >>> p, lost = openpbr_inputs(mf.MicrofacetBRDF(mf.GGX(alpha_x=0.2, alpha_y=0.1), mf.fresnel.Schlick([0.9, 0.6, 0.5])))
    >>> p["base_metalness"], p["base_color"], p["specular_roughness_anisotropy"]
    (1.0, [0.9, 0.6, 0.5], 0.5)
    >>> round(p["specular_roughness"], 4), lost
    (0.3976, [])
    """
    from .. import fresnel as fr
    from .gltf import metal_f0
    a = analyse(brdf)
    lost: list[str] = list(a.notes)
    p: dict = {"base_weight": 1.0, "specular_weight": 1.0, "base_diffuse_roughness": 0.0}
    if not a.lobes:
        p.update(base_color=a.base.tolist(), base_metalness=0.0, specular_weight=0.0)
        return p, lost
    lobe = a.lobes[0]
    for other in a.lobes[1:]:
        lost.append(f"second lobe (alpha {other.alpha1:.4g}) dropped (OpenPBR has one specular lobe)")
    if lobe.family != "ggx":
        lost.append("Beckmann lobe exported as GGX")
    aniso = 1.0 - min(lobe.alpha2 / lobe.alpha1, 1.0)
    r2 = min(lobe.alpha1 / math.sqrt(2.0 / (1.0 + (1.0 - aniso) ** 2)), 1.0)
    p.update(specular_roughness=math.sqrt(r2), specular_roughness_anisotropy=aniso)
    if aniso > 0:
        p["tangent_rotation"] = lobe.phi      # not an input: written as geometry_tangent (rotate3d)
    metal = metal_f0(lobe.fresnel) if a.base is None else None
    if metal is not None or a.base is None:
        if isinstance(lobe.fresnel, fr.F82Tint):
            f0, f82 = lobe.fresnel.f0, lobe.fresnel.f82
        elif isinstance(lobe.fresnel, fr.Conductor):
            t = fr.F82Tint.from_conductor(lobe.fresnel.eta, lobe.fresnel.k)
            f0, f82 = t.f0, t.f82
        else:
            f0, f90 = schlick_of(lobe.fresnel)
            schlick1 = f0 + (1.0 - f0) * (1.0 - F82_COS) ** 5
            f82 = np.clip((f0 + (f90 - f0) * (1.0 - F82_COS) ** 5) / schlick1, 0.0, 1.0)
            if np.any(np.abs(f90 - 1.0) > 1e-3):
                lost.append(f"Schlick f90 {np.round(f90, 3).tolist()} exported as the F82 tint through F(82 deg)")
        p.update(base_metalness=1.0, base_color=np.asarray(f0, float).tolist(),
                 specular_color=np.asarray(f82, float).tolist())
    else:
        f0, f90 = schlick_of(lobe.fresnel)
        m = float(np.clip(np.mean(f0), 1e-6, 0.999))
        q = math.sqrt(m)
        p.update(base_metalness=0.0, base_color=a.base.tolist(), specular_ior=(1 + q) / (1 - q),
                 specular_color=np.clip(f0 / m, 0.0, 1.0).tolist())
        lost.append("lobe over a base exported as OpenPBR's dielectric (Fresnel of specular_ior, base under the "
                    "lobe's albedo)")
    if a.coat is not None:
        p.update(coat_weight=1.0, coat_roughness=math.sqrt(math.sqrt(a.coat.alpha1 * a.coat.alpha2)),
                 coat_ior=float(np.mean(getattr(a.coat.fresnel, "eta", 1.5))), coat_darkening=0.0)
    return p, lost


def openpbr_brdf(p: dict):
    """The library BRDF of ``open_pbr_surface`` inputs (the inverse mapping, as the OpenPBR
    specification reads them: metal = GGX lobe with F82 tint; dielectric = GGX lobe with the
    dielectric Fresnel of ``specular_ior`` tinted by ``specular_color`` over the Lambertian
    ``base_color``, coupled by the lobe's albedo; coat = a dielectric coat layer).

    Parameters
    ----------
    p : dict
        ``open_pbr_surface`` inputs (:func:`openpbr_inputs`); missing ones take OpenPBR's
        defaults.

    Returns
    -------
    BRDF
        A :class:`~microfacet.MicrofacetBRDF`, a :class:`~microfacet.fit.SumBRDF` with a
        Lambertian base, a :class:`~microfacet.Lambertian`, or a
        :class:`~microfacet.layered.LayeredBRDF` when ``coat_weight > 0``.

    Examples
    --------
    >>> b = openpbr_brdf({"base_metalness": 1.0, "base_color": [0.9, 0.6, 0.5], "specular_roughness": 0.5})
    >>> type(b).__name__, type(b.fresnel).__name__, float(b.distribution.alpha_x)
    ('MicrofacetBRDF', 'F82Tint', 0.25)
    """
    from .. import fresnel as fr
    from ..brdf import Lambertian, MicrofacetBRDF
    from ..distributions import GGX
    from ..layered import LayeredBRDF
    r2 = float(p.get("specular_roughness", 0.3)) ** 2
    a = float(p.get("specular_roughness_anisotropy", 0.0))
    at = max(r2 * math.sqrt(2.0 / (1.0 + (1.0 - a) ** 2)), 1e-4)
    ab = max((1.0 - a) * at, 1e-4)
    dist = GGX(alpha=at) if a == 0 else GGX.from_ellipse(at, ab, float(p.get("tangent_rotation", 0.0)))
    if float(p.get("specular_weight", 1.0)) == 0.0:
        out = Lambertian(p["base_color"])
    elif float(p.get("base_metalness", 0.0)) >= 1.0:
        out = MicrofacetBRDF(dist, fr.F82Tint(p["base_color"], p.get("specular_color", 1.0)))
    else:
        ior = float(p.get("specular_ior", 1.5))
        f0 = ((ior - 1) / (ior + 1)) ** 2 * np.asarray(p.get("specular_color", [1, 1, 1]), float)
        lobe = MicrofacetBRDF(dist, fr.Schlick(np.clip(f0, 0, 1), np.asarray(p.get("specular_color", 1.0))))
        from ..fit.analytic import SumBRDF
        # OpenPBR scales the base by the lobe's albedo complement; the library's coat coupling does it for a
        # Dielectric Fresnel: for a tinted Schlick, the sum with the base weighted by 1 - F0 at normal incidence.
        out = SumBRDF(lobe, Lambertian(np.asarray(p["base_color"], float) * (1.0 - float(np.max(f0)))))
    if float(p.get("coat_weight", 0.0)) > 0:
        rc = max(float(p.get("coat_roughness", 0.0)) ** 2, 1e-4)
        out = LayeredBRDF(MicrofacetBRDF(GGX(alpha=rc), fr.Dielectric(float(p.get("coat_ior", 1.6)))), out)
    return out


def pbrlib_brdf(brdf):
    """The library BRDF the pbrlib graph evaluates (the inverse mapping): the same tree with
    Beckmann lobes as GGX of the same ellipse, mean slopes dropped, Fresnel tables as
    their least-squares Schlick and a diffuse seen through its surface
    (:class:`~microfacet.diffuse.TransmittedLambertian`) as the Lambertian of the same mean
    albedo (:func:`~microfacet.export.analysis.equivalent_lambertian`), as the graph holds them
    (MaterialX's own anisotropic shadowing is not modelled).

    Parameters
    ----------
    brdf : BRDF
        An analytic BRDF tree.

    Returns
    -------
    BRDF
        The same tree, every lobe GGX.

    Examples
    --------
    >>> import microfacet as mf
    >>> b = pbrlib_brdf(mf.MicrofacetBRDF(mf.Beckmann(alpha=0.2), mf.fresnel.Schlick(0.9)))
    >>> type(b.distribution).__name__, float(b.distribution.alpha_x)
    ('GGX', 0.2)
    """
    from .. import fresnel as fr
    from ..brdf import Lambertian, MicrofacetBRDF
    from ..diffuse import TransmittedLambertian
    from ..distributions import GGX, Beckmann
    from ..fit.analytic import SumBRDF
    from .analysis import equivalent_lambertian

    def lobe(b):
        d = b.distribution
        dist = GGX(alpha_x=d.alpha_x, alpha_y=d.alpha_y, rho=d.rho)
        f = b.fresnel
        if isinstance(f, fr.Tabulated):
            f = fr.Schlick(*schlick_of(f))
        return MicrofacetBRDF(dist, f)

    def walk(b):
        if isinstance(b, MicrofacetBRDF) and isinstance(b.distribution, (GGX, Beckmann)):
            return lobe(b)
        if isinstance(b, SumBRDF):
            return SumBRDF(*(walk(p) for p in b.brdfs), weights=b.weights)
        if isinstance(b, TransmittedLambertian):
            return Lambertian(equivalent_lambertian(b))
        if type(b).__name__ == "LayeredBRDF":
            from ..layered import LayeredBRDF
            return LayeredBRDF(walk(b.coat), walk(b.base))
        return b
    return walk(brdf)


def mtlx_document(brdf, openpbr: bool = True):
    """``(document, lost)``: a MaterialX document holding ``M_microfacet_exact`` (the pbrlib
    graph) and, with ``openpbr``, ``M_microfacet_openpbr`` (an ``open_pbr_surface``).

    Parameters
    ----------
    brdf : BRDF
        An analytic BRDF tree (:func:`~microfacet.export.analysis.analyse`).
    openpbr : bool
        Add the ``open_pbr_surface`` material.

    Returns
    -------
    document : MaterialX.Document
        The document (MaterialX 1.39).
    lost : list of str
        What the pbrlib graph and the OpenPBR surface could not hold.

    Examples
    --------
    >>> import microfacet as mf
    >>> doc, lost = mtlx_document(mf.MicrofacetBRDF(mf.GGX(alpha_x=0.2, alpha_y=0.1)))
    >>> [m.getName() for m in doc.getMaterialNodes()]
    ['M_microfacet_exact', 'M_microfacet_openpbr']
    >>> lost[0]
    "lobe0: MaterialX's anisotropic Smith term uses sqrt(alpha1 alpha2) ..."
    """
    mx = _mx()
    doc = mx.createDocument()
    a = analyse(brdf)
    lost: list[str] = list(a.notes)
    _pbrlib(mx, doc, a, lost)
    if openpbr:
        p, lost_p = openpbr_inputs(brdf)
        lost += [f"open_pbr_surface: {x}" for x in lost_p]
        sh = doc.addNode("open_pbr_surface", "SR_microfacet_openpbr", "surfaceshader")
        for k, v in p.items():
            if k == "tangent_rotation":
                graph = doc.addNodeGraph("NG_openpbr_tangent")
                rot = _tangent(mx, graph, v, "spec")
                out = graph.addOutput("out", "vector3")
                out.setConnectedNode(rot)
                sh.addInput("geometry_tangent", "vector3").setConnectedOutput(out)
            elif isinstance(v, list):
                sh.setInputValue(k, _color(mx, v))
            else:
                sh.setInputValue(k, float(v))
        doc.addMaterialNode("M_microfacet_openpbr", sh)
    return doc, lost


def validate(doc) -> list[str]:
    """MaterialX's own ``validate()`` of ``doc`` with the standard libraries, plus a check that
    every node has a nodedef (unknown node types pass ``validate``); the list of problems
    (empty when valid).

    Parameters
    ----------
    doc : MaterialX.Document
        A document (:func:`mtlx_document`); its data library is set to the standard one.

    Returns
    -------
    list of str
        The problems found, empty when the document is valid.

    Examples
    --------
    >>> import microfacet as mf
    >>> doc, _ = mtlx_document(mf.MicrofacetBRDF(mf.GGX(alpha=0.1), mf.fresnel.Conductor()))
    >>> validate(doc)
    []
    """
    mx = _mx()
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    doc.setDataLibrary(lib)
    ok, message = doc.validate()
    problems = [] if ok else [line for line in message.splitlines() if line.strip()]
    for elem in doc.traverseTree():
        if elem.isA(mx.Node) and elem.getNodeDef() is None:
            problems.append(f"node {elem.getNamePath()} ({elem.getCategory()}) has no nodedef")
    return problems


def glsl_source(doc, material: str = "M_microfacet_exact") -> tuple[str, str]:
    """``(vertex, pixel)`` GLSL of one material of ``doc`` from MaterialX's GLSL generator.

    Parameters
    ----------
    doc : MaterialX.Document
        A document (:func:`mtlx_document`).
    material : str
        The material node's name (``"M_microfacet_exact"`` or ``"M_microfacet_openpbr"``).

    Returns
    -------
    vertex, pixel : str
        The two stages' GLSL source.

    Raises
    ------
    ValueError
        ``doc`` has no material ``material``.

    Examples
    --------
    >>> import microfacet as mf
    >>> doc, _ = mtlx_document(mf.MicrofacetBRDF(mf.GGX(alpha=0.1)))
    >>> vertex, pixel = glsl_source(doc)
    >>> pixel.startswith("#version"), "void main()" in pixel
    (True, True)
    """
    mx = _mx()
    import MaterialX.PyMaterialXGenGlsl as gen_glsl
    import MaterialX.PyMaterialXGenShader as gen
    lib = mx.createDocument()
    search = mx.getDefaultDataSearchPath()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), search, lib)
    doc.setDataLibrary(lib)
    generator = gen_glsl.GlslShaderGenerator.create()      # kept referenced while the context uses it
    ctx = gen.GenContext(generator)
    ctx.registerSourceCodeSearchPath(search)
    mat = doc.getChild(material)
    if mat is None:
        raise ValueError(f"the document has no material {material!r}")
    shader = generator.generate(material, mx.getShaderNodes(mat)[0], ctx)
    return shader.getSourceCode(gen.VERTEX_STAGE), shader.getSourceCode(gen.PIXEL_STAGE)


def write_mtlx(doc, path) -> Path:
    """Write ``doc`` to ``path`` (``.mtlx``; its folder is created).

    Parameters
    ----------
    doc : MaterialX.Document
        A document (:func:`mtlx_document`).
    path : str or os.PathLike
        The file to write.

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> import microfacet as mf
    >>> doc, _ = mtlx_document(mf.MicrofacetBRDF(mf.GGX(alpha=0.1)))
    >>> write_mtlx(doc, "lobe.mtlx").read_text().count("<surfacematerial")
    2
    """
    mx = _mx()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mx.writeToXmlFile(doc, str(path))
    return path
