"""USD (``.usda``) materials of library BRDFs: a UsdPreviewSurface, plus the MaterialX
OpenPBR surface under the ``mtlx`` render context, bound to a sphere.

UsdPreviewSurface (USD 2.x specification) is isotropic GGX with ``alpha = roughness^2``
(Hydra Storm): the ellipse becomes ``roughness = (alpha1 alpha2)^(1/4)``; a metal
(no base) is ``metallic 1``, ``diffuseColor = F(0)``; otherwise the specular workflow,
``specularColor = f0`` (Schlick towards 1 at grazing) and ``diffuseColor`` the base; a coat
is ``clearcoat 1``, ``clearcoatRoughness = sqrt(alpha_coat)``. The OpenPBR inputs are those
of :func:`microfacet.export.mtlx.openpbr_inputs`.

Examples
--------
>>> import microfacet as mf
>>> inputs, lost = preview_inputs(mf.MicrofacetBRDF(mf.GGX(alpha=0.04)))
>>> round(inputs["roughness"], 3), inputs["metallic"]
(0.2, 1.0)
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .analysis import analyse, schlick_of

__all__ = ["preview_inputs", "preview_brdf", "write_usda", "read_bound_inputs", "validation_errors", "import_pxr", "MTLX_SHADER_ID"]

#: The shader id of MaterialX's OpenPBR surface node definition.
MTLX_SHADER_ID = "ND_open_pbr_surface_surfaceshader"


def import_pxr():
    """Import ``pxr`` once no kernel compiles on the background thread: loading pxr's
    libraries while that thread imports Numba's deadlocks (both inside the dynamic loader).

    Returns
    -------
    module
        The ``pxr`` package (usd-core), with ``pxr.Usd`` loaded.

    Examples
    --------
    >>> pxr = import_pxr()
    >>> pxr.__name__, hasattr(pxr, "Usd")
    ('pxr', True)
    """
    from .. import kernels
    kernels.ready(wait=None)
    import pxr.Usd  # noqa: F401
    return pxr


def preview_inputs(brdf) -> tuple[dict, list[str]]:
    """``(inputs, lost)``: UsdPreviewSurface inputs of a library BRDF tree (module docstring).

    Parameters
    ----------
    brdf : BRDF
        An analytic BRDF tree (:func:`~microfacet.export.analysis.analyse`).

    Returns
    -------
    inputs : dict
        UsdPreviewSurface input name -> float, int or RGB list.
    lost : list of str
        What UsdPreviewSurface could not hold (anisotropy, second lobes, coat index, ...).

    Examples
    --------
    >>> import microfacet as mf
    >>> p, lost = preview_inputs(mf.MicrofacetBRDF(mf.GGX(alpha_x=0.16, alpha_y=0.04)))
    >>> round(p["roughness"], 4), p["metallic"], lost
    (0.2828, 1.0, ['anisotropy dropped: UsdPreviewSurface is isotropic (alpha = sqrt(alpha1 alpha2))'])
    """
    from .gltf import metal_f0
    a = analyse(brdf)
    lost: list[str] = list(a.notes)
    p: dict = {"useSpecularWorkflow": 0, "metallic": 0.0, "roughness": 1.0, "diffuseColor": [0.0, 0.0, 0.0],
               "specularColor": [0.0, 0.0, 0.0]}
    if a.lobes:
        lobe = a.lobes[0]
        p["roughness"] = float(min((lobe.alpha1 * lobe.alpha2) ** 0.25, 1.0))
        if not lobe.isotropic:
            lost.append("anisotropy dropped: UsdPreviewSurface is isotropic (alpha = sqrt(alpha1 alpha2))")
        if lobe.family != "ggx":
            lost.append("Beckmann lobe exported as GGX")
        for other in a.lobes[1:]:
            lost.append(f"second lobe (alpha {other.alpha1:.4g}) dropped")
        metal = metal_f0(lobe.fresnel) if a.base is None else None
        if metal is not None:
            p.update(metallic=1.0, diffuseColor=metal.tolist())
        else:
            f0, f90 = schlick_of(lobe.fresnel)
            if np.any(np.abs(f90 - 1.0) > 1e-3):
                lost.append(f"Schlick f90 {np.round(f90, 3).tolist()} exported as 1 (UsdPreviewSurface)")
            p.update(useSpecularWorkflow=1, specularColor=f0.tolist())
            if a.base is not None:
                p["diffuseColor"] = a.base.tolist()
    else:
        p["diffuseColor"] = a.base.tolist()
    if a.coat is not None:
        p.update(clearcoat=1.0, clearcoatRoughness=float(math.sqrt(math.sqrt(a.coat.alpha1 * a.coat.alpha2))))
        lost.append("coat index exported as UsdPreviewSurface's fixed 1.5")
    return p, lost


def preview_brdf(p: dict):
    """The library BRDF of UsdPreviewSurface inputs (the inverse mapping): GGX
    ``alpha = roughness^2`` with Schlick towards 1 (``diffuseColor`` as F0 when metallic,
    ``specularColor`` in the specular workflow, 0.04 otherwise) plus the Lambertian
    ``diffuseColor`` (non-metals), under a dielectric 1.5 coat when ``clearcoat`` is set.

    Parameters
    ----------
    p : dict
        UsdPreviewSurface inputs (:func:`preview_inputs`, :func:`read_bound_inputs`);
        missing ones take the specification's defaults.

    Returns
    -------
    BRDF
        A :class:`~microfacet.MicrofacetBRDF`, a :class:`~microfacet.fit.SumBRDF` with a
        Lambertian, or a :class:`~microfacet.layered.LayeredBRDF` with a coat.

    Examples
    --------
    >>> b = preview_brdf({"roughness": 0.5, "diffuseColor": [0.5, 0.1, 0.1]})     # a non-metal
    >>> [type(part).__name__ for part in b.brdfs]
    ['MicrofacetBRDF', 'Lambertian']
    >>> float(b.brdfs[0].distribution.alpha_x), b.brdfs[0].fresnel.f0.tolist()
    (0.25, [0.04, 0.04, 0.04])
    """
    from .. import fresnel as fr
    from ..brdf import Lambertian, MicrofacetBRDF
    from ..distributions import GGX
    from ..fit.analytic import SumBRDF
    alpha = max(float(p.get("roughness", 0.5)) ** 2, 1e-4)
    metallic = float(p.get("metallic", 0.0))
    if p.get("useSpecularWorkflow", 0):
        f0 = np.asarray(p.get("specularColor", [0, 0, 0]), float)
        metallic = 0.0
    else:
        f0 = metallic * np.asarray(p.get("diffuseColor", [0, 0, 0]), float) + (1 - metallic) * 0.04
    out = MicrofacetBRDF(GGX(alpha=alpha), fr.Schlick(np.clip(f0, 0, 1), 1.0))
    diffuse = (1 - metallic) * np.asarray(p.get("diffuseColor", [0, 0, 0]), float)
    if np.any(diffuse > 0):
        out = SumBRDF(out, Lambertian(np.clip(diffuse, 0, 1)))
    if float(p.get("clearcoat", 0.0)) > 0:
        from ..layered import LayeredBRDF
        rc = max(float(p.get("clearcoatRoughness", 0.01)) ** 2, 1e-4)
        out = LayeredBRDF(MicrofacetBRDF(GGX(alpha=rc), fr.Dielectric(1.5)), out)
    return out


def write_usda(brdf, path, mtlx_file: str | None = None, mtlx: bool = True) -> tuple[Path, list[str]]:
    """Write ``path`` (``.usda``): ``/Root/Sphere`` (a ``Sphere`` prim and a ``Mesh`` copy, for
    importers that bind only meshes) bound to ``/Root/Materials/Microfacet`` whose
    ``outputs:surface`` is the UsdPreviewSurface and ``outputs:mtlx:surface`` the OpenPBR
    surface (``info:id`` :data:`MTLX_SHADER_ID`; ``mtlx_file``, the exported ``.mtlx``, is
    noted in the material's ``customData``); ``mtlx=False``: the preview surface only.
    ``pxr.UsdValidation`` passes the file without errors except, for the OpenPBR shader, a
    ``MissingShaderIdInRegistry`` where USD was built without MaterialX (usd-core).
    Returns ``(path, lost)``.

    Parameters
    ----------
    brdf : BRDF
        An analytic BRDF tree.
    path : str or os.PathLike
        The ``.usda`` to write (its folder is created).
    mtlx_file : str, optional
        The exported ``.mtlx`` to note in the material's ``customData``.
    mtlx : bool
        Add the OpenPBR surface under the ``mtlx`` render context.

    Returns
    -------
    path : Path
        ``path``.
    lost : list of str
        What the two surfaces could not hold.

    Examples
    --------
    >>> import microfacet as mf
    >>> path, lost = write_usda(mf.MicrofacetBRDF(mf.GGX(alpha=0.04)), "chrome.usda")
    >>> round(read_bound_inputs(path)["roughness"], 4), MTLX_SHADER_ID
    (0.2, 'ND_open_pbr_surface_surfaceshader')
    """
    import_pxr()
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade

    from .gltf import sphere_mesh
    from .mtlx import openpbr_inputs
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    preview, lost = preview_inputs(brdf)
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, "/Root")
    stage.SetDefaultPrim(root.GetPrim())
    UsdGeom.Sphere.Define(stage, "/Root/Sphere").GetRadiusAttr().Set(1.0)
    pos, nrm, _, _, idx = sphere_mesh(32, 64)
    mesh = UsdGeom.Mesh.Define(stage, "/Root/SphereMesh")
    mesh.GetPointsAttr().Set([Gf.Vec3f(*map(float, p)) for p in pos])
    mesh.GetFaceVertexCountsAttr().Set([3] * (len(idx) // 3))
    mesh.GetFaceVertexIndicesAttr().Set([int(i) for i in idx])
    mesh.GetNormalsAttr().Set([Gf.Vec3f(*map(float, n)) for n in nrm])
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    mesh.GetSubdivisionSchemeAttr().Set(UsdGeom.Tokens.none)
    mesh.GetExtentAttr().Set([Gf.Vec3f(-1, -1, -1), Gf.Vec3f(1, 1, 1)])
    UsdGeom.Sphere(stage.GetPrimAtPath("/Root/Sphere")).GetExtentAttr().Set([Gf.Vec3f(-1, -1, -1),
                                                                              Gf.Vec3f(1, 1, 1)])
    UsdGeom.Xformable(mesh).AddTranslateOp().Set(Gf.Vec3d(3.0, 0.0, 0.0))
    material = UsdShade.Material.Define(stage, "/Root/Materials/Microfacet")
    shader = UsdShade.Shader.Define(stage, "/Root/Materials/Microfacet/PreviewSurface")
    shader.CreateIdAttr("UsdPreviewSurface")
    for k, v in preview.items():
        if isinstance(v, list):
            shader.CreateInput(k, Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*map(float, v)))
        elif k == "useSpecularWorkflow":
            shader.CreateInput(k, Sdf.ValueTypeNames.Int).Set(int(v))
        else:
            shader.CreateInput(k, Sdf.ValueTypeNames.Float).Set(float(v))
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    opbr, lost_p = openpbr_inputs(brdf) if mtlx else ({}, [])
    lost += [f"mtlx (open_pbr_surface): {x}" for x in lost_p]
    ms = UsdShade.Shader.Define(stage, "/Root/Materials/Microfacet/OpenPBR")
    ms.CreateIdAttr(MTLX_SHADER_ID)
    for k, v in opbr.items():
        if k == "tangent_rotation":
            lost.append("mtlx (open_pbr_surface) in USD: the anisotropy direction (rotated tangent) is in the .mtlx "
                        "file only")
        elif isinstance(v, list):
            ms.CreateInput(k, Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*map(float, v)))
        else:
            ms.CreateInput(k, Sdf.ValueTypeNames.Float).Set(float(v))
    if mtlx:
        material.CreateSurfaceOutput("mtlx").ConnectToSource(ms.ConnectableAPI(), "surface")
    else:
        stage.RemovePrim(ms.GetPath())
    if mtlx_file:
        material.GetPrim().SetCustomDataByKey("microfacet:mtlx", str(mtlx_file))
    for prim in ("/Root/Sphere", "/Root/SphereMesh"):
        p = stage.GetPrimAtPath(prim)
        UsdShade.MaterialBindingAPI.Apply(p).Bind(material)
    stage.GetRootLayer().Save()
    return path, lost


def validation_errors(path) -> list[tuple[str, str, str]]:
    """``(name, prim path or "", message)`` of each error ``pxr.UsdValidation`` (all its
    registered validators) reports on the USD file ``path``.

    Parameters
    ----------
    path : str or os.PathLike
        A USD file.

    Returns
    -------
    list of (str, str, str)
        The errors (warnings are left out); empty when the file passes.

    Examples
    --------
    A preview surface alone passes; the OpenPBR shader's id is known only to a USD built
    with MaterialX:

    >>> import microfacet as mf
    >>> path, _ = write_usda(mf.MicrofacetBRDF(mf.GGX(alpha=0.1)), "preview.usda", mtlx=False)
    >>> validation_errors(path)
    []
    """
    import_pxr()
    from pxr import Usd, UsdValidation
    reg = UsdValidation.ValidationRegistry()
    ctx = UsdValidation.ValidationContext(reg.GetOrLoadAllValidators())
    out = []
    for e in ctx.Validate(Usd.Stage.Open(str(path))):
        if e.GetType() == UsdValidation.ValidationErrorType.Error:
            sites = [str(s.GetPrim().GetPath()) for s in e.GetSites() if s.IsPrim()]
            out.append((e.GetName(), sites[0] if sites else "", e.GetMessage()))
    return out


def read_bound_inputs(path, prim: str = "/Root/Sphere", context: str = "") -> dict:
    """The inputs (name -> value) of the surface shader bound to ``prim`` in a USD file, for
    the render ``context`` (``""``: universal, UsdPreviewSurface; ``"mtlx"``: OpenPBR).

    Parameters
    ----------
    path : str or os.PathLike
        A USD file (:func:`write_usda`).
    prim : str
        The bound prim's path.
    context : str
        The render context of the material's surface output.

    Returns
    -------
    dict
        Input name -> value (vectors and colours as lists).

    Raises
    ------
    ValueError
        USD could not open ``path``.

    Examples
    --------
    >>> import microfacet as mf
    >>> path, _ = write_usda(mf.MicrofacetBRDF(mf.GGX(alpha=0.25), mf.fresnel.Schlick([0.9, 0.6, 0.5])), "m.usda")
    >>> read_bound_inputs(path)["metallic"], round(read_bound_inputs(path, context="mtlx")["specular_roughness"], 3)
    (1.0, 0.5)
    """
    import_pxr()
    from pxr import Usd, UsdShade
    stage = Usd.Stage.Open(str(path))
    if not stage:
        raise ValueError(f"{path}: USD could not open the file")
    mat, _ = UsdShade.MaterialBindingAPI(stage.GetPrimAtPath(prim)).ComputeBoundMaterial()
    shader = mat.ComputeSurfaceSource(context)[0]
    out = {}
    for i in shader.GetInputs():
        v = i.Get()
        out[i.GetBaseName()] = list(v) if hasattr(v, "__len__") and not isinstance(v, str) else v
    return out
