"""microfacet.export: mappings, their inverses, and each real consumer that is installed here
(pygltflib, MaterialX validate + GLSL generation + GL compile, usd-core + UsdValidation)."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

import microfacet as mf
from microfacet import fresnel as fr
from microfacet.export import analyse, export, gltf_brdf, gltf_material, read_material, write_glb
from microfacet.export.gltf import alphas_of, roughness_anisotropy
from microfacet.fit import SumBRDF
from microfacet.metrics import ImageError

CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")


def _need(module: str):
    """Import ``module`` or skip (fail under CI=true: make setup installs the export extra)."""
    try:
        return pytest.importorskip(module, reason=f"{module} absent: pip install 'microfacet[export]'")
    except pytest.skip.Exception:
        if CI:
            pytest.fail(f"{module} is missing under CI (make setup installs the export extra)")
        raise


def _err(ref, fit):
    return ImageError(ref, size=24)(fit)


METAL_ISO = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), fr.Schlick([0.95, 0.64, 0.54]))
METAL_ANISO = mf.MicrofacetBRDF(mf.GGX.from_ellipse(0.35, 0.08, 0.6), fr.Schlick([0.9, 0.8, 0.5]))
PLASTIC = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.1), fr.Schlick(0.04, 1.0)), mf.Lambertian([0.5, 0.2, 0.1]))


def test_roughness_anisotropy_inverts():
    for a1, a2 in [(0.3, 0.3), (0.5, 0.05), (0.9, 0.2), (1.0, 0.01)]:
        r, s, lost = roughness_anisotropy(a1, a2)
        at, ab = alphas_of(r, s)
        assert (at, ab) == pytest.approx((a1, a2), rel=1e-12) and not lost
    assert roughness_anisotropy(1.5, 0.1)[2]        # clipped: said


def test_analysis_orders_lobes_by_albedo():
    weak = mf.MicrofacetBRDF(mf.GGX(alpha=0.05), fr.Schlick(0.02, 0.02))
    strong = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fr.Schlick(0.5, 1.0))
    a = analyse(SumBRDF(weak, strong, mf.Lambertian(0.1)))
    assert a.lobes[0].alpha1 == pytest.approx(0.3) and a.base == pytest.approx([0.1] * 3)
    with pytest.raises(mf.MicrofacetError, match="GGX and Beckmann"):
        analyse(mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), resolution=16))


@pytest.mark.parametrize("brdf", [METAL_ISO, METAL_ANISO, PLASTIC], ids=["metal", "aniso", "plastic"])
def test_gltf_mapping_is_exact_for_what_gltf_holds(brdf):
    """Metals (Schlick f90 = 1), rotated anisotropy and a dielectric lobe + base map to glTF and
    back with the image error of an exact copy (0 for the lobes; the base only through glTF's
    Fresnel weighting, compensated on average)."""
    mat, lost = gltf_material(brdf)
    e = _err(brdf, gltf_brdf(mat))
    assert e < (0.02 if brdf is PLASTIC else 1e-9), (e, lost)


def test_gltf_lossy_cases_are_reported_and_measured():
    beck = mf.MicrofacetBRDF(mf.Beckmann(alpha=0.2, mean_slope=(0.1, 0.0)), fr.F82Tint([0.9, 0.6, 0.5], 0.7))
    mat, lost = gltf_material(beck)
    text = " ".join(lost)
    assert "Beckmann" in text and "mean slope" in text and "F82" in text
    assert _err(beck, gltf_brdf(mat)) > 1e-3


def test_glb_round_trips_through_pygltflib(tmp_path):
    pygltflib = _need("pygltflib")
    mat, _ = gltf_material(METAL_ANISO)
    path = write_glb(mat, tmp_path / "s.glb")
    gl = pygltflib.GLTF2().load(str(path))
    back = read_material(path)
    assert back["pbrMetallicRoughness"]["roughnessFactor"] == pytest.approx(np.sqrt(0.08))
    an = back["extensions"]["KHR_materials_anisotropy"]
    assert an["anisotropyRotation"] == pytest.approx(0.6)
    assert set(gl.extensionsUsed) == {"KHR_materials_anisotropy"}
    prim = gl.meshes[0].primitives[0]
    assert prim.attributes.TANGENT is not None and prim.material == 0
    blob = gl.binary_blob()
    acc = gl.accessors[prim.attributes.POSITION]
    view = gl.bufferViews[acc.bufferView]
    pos = np.frombuffer(blob[view.byteOffset:view.byteOffset + view.byteLength], np.float32).reshape(-1, 3)
    assert np.allclose(np.linalg.norm(pos, axis=1), 1.0, atol=1e-6)
    assert _err(METAL_ANISO, gltf_brdf(back)) < 1e-6


def _coated():
    from microfacet.layered import LayeredBRDF
    return LayeredBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.04), fr.Dielectric(1.5)),
                       SumBRDF(mf.MicrofacetBRDF(mf.GGX.from_ellipse(0.3, 0.1, 0.4), fr.Conductor()),
                               mf.Lambertian(0.2)))


@pytest.mark.parametrize("which", ["aniso", "coat", "two_lobes"])
def test_mtlx_validates_and_generates_glsl(which, tmp_path):
    mx = _need("MaterialX")
    from microfacet.export.mtlx import glsl_source, mtlx_document, validate, write_mtlx
    brdf = {"aniso": METAL_ANISO, "coat": _coated(),
            "two_lobes": SumBRDF(METAL_ISO, mf.MicrofacetBRDF(mf.GGX(alpha=0.03), fr.Schlick(0.1, 0.1)),
                                 mf.Lambertian(0.05))}[which]
    doc, _ = mtlx_document(brdf)
    assert validate(doc) == []
    path = write_mtlx(doc, tmp_path / "m.mtlx")
    again = mx.createDocument()
    mx.readFromXmlFile(again, str(path))
    assert validate(again) == []
    categories = {n.getCategory() for n in again.getNodeGraph("NG_microfacet").getNodes()}
    expected = {"aniso": {"generalized_schlick_bsdf", "rotate3d"}, "coat": {"layer", "conductor_bsdf",
                "dielectric_bsdf", "oren_nayar_diffuse_bsdf", "add"}, "two_lobes": {"add"}}[which]
    assert expected <= categories
    for material in ("M_microfacet_exact", "M_microfacet_openpbr"):
        vertex, pixel = glsl_source(again, material)
        assert "void main" in pixel and "void main" in vertex


def test_mtlx_glsl_compiles_on_gl():
    _need("MaterialX")
    moderngl = pytest.importorskip("moderngl", reason="moderngl absent")
    from microfacet.export.mtlx import glsl_source, mtlx_document
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=400)
    except Exception as e:                         # noqa: BLE001 - no EGL/Mesa here
        if CI:
            raise
        pytest.skip(f"no OpenGL 4 context on EGL: {e}")
    doc, _ = mtlx_document(_coated())
    vertex, pixel = glsl_source(doc)
    prog = ctx.program(vertex_shader=vertex, fragment_shader=pixel)
    assert prog is not None
    ctx.release()


def test_openpbr_roughness_mapping_inverts():
    from microfacet.export.mtlx import openpbr_brdf, openpbr_inputs
    p, _ = openpbr_inputs(METAL_ANISO)
    b = openpbr_brdf(p)
    a1, a2, phi = b.distribution.ellipse
    assert (float(a1), float(a2), float(phi)) == pytest.approx((0.35, 0.08, 0.6), rel=1e-9)
    p82, _ = openpbr_inputs(mf.MicrofacetBRDF(mf.GGX(alpha=0.2), fr.F82Tint([0.9, 0.6, 0.5], [0.8, 0.7, 0.9])))
    assert p82["specular_color"] == pytest.approx([0.8, 0.7, 0.9]) and p82["base_metalness"] == 1.0


def test_usd_opens_binds_and_validates(tmp_path):
    _need("pxr")
    from microfacet.export.usd import preview_brdf, read_bound_inputs, validation_errors, write_usda
    path, _ = write_usda(PLASTIC, tmp_path / "m.usda", mtlx_file="m.mtlx")
    for prim in ("/Root/Sphere", "/Root/SphereMesh"):
        p = read_bound_inputs(path, prim)
        assert p["roughness"] == pytest.approx(np.sqrt(0.1), rel=1e-6)
        assert p["diffuseColor"] == pytest.approx([0.5, 0.2, 0.1], rel=1e-6)
    m = read_bound_inputs(path, context="mtlx")
    assert m["base_color"] == pytest.approx([0.5, 0.2, 0.1], rel=1e-6) and "specular_ior" in m
    assert _err(PLASTIC, preview_brdf(read_bound_inputs(path))) < 0.05
    # usd-core has no MaterialX plugin: the OpenPBR shader id is its only complaint
    assert {name for name, *_ in validation_errors(path)} <= {"MissingShaderIdInRegistry"}
    plain, _ = write_usda(PLASTIC, tmp_path / "p.usda", mtlx=False)
    assert validation_errors(plain) == []


def test_export_of_a_brdf_writes_the_report(tmp_path):
    _need("pygltflib")
    report = export(METAL_ANISO, "gltf", tmp_path / "a")
    assert report["file"].endswith("a.glb")
    saved = json.loads((tmp_path / "a.glb.export.json").read_text())
    assert saved["image_error"]["exported_vs_fit"]["gltf"] < 1e-6
    assert "Not carried" in (tmp_path / "a.glb.export.md").read_text()


def test_cli_exports_a_fit_file(tmp_path, corpus):
    for m in ("pygltflib", "MaterialX", "pxr"):
        _need(m)
    from microfacet.cli import main
    fit_path = tmp_path / "m.npz"
    data = corpus("merl/chrome")
    assert main(["fit", str(data), "-o", str(fit_path), "--no-picture", "--resolution", "32"]) == 0
    for to, suffix in (("gltf", ".glb"), ("mtlx", ".mtlx"), ("usd", ".usda")):
        assert main(["export", str(fit_path), "--to", to, "-o", str(tmp_path / "out")]) == 0
        rep = json.loads((tmp_path / f"out{suffix}.export.json").read_text())
        assert rep["model"] != "tabulated"
        assert all(np.isfinite(v) for v in rep["image_error"]["exported_vs_tabulated"].values())
    assert main(["export", str(fit_path), "--to", "gltf", "--model", "tabulated", "-o", str(tmp_path / "t")]) == 1


def test_cli_exports_a_measured_file_in_one_command(tmp_path, corpus, capsys):
    """A measured file is fitted first (the fit files kept beside OUT, as 'microfacet fit'
    writes them) and its best fit exported; the report names that fit file. A file that is
    neither a fit nor a measured BRDF: one line, nothing written."""
    _need("pygltflib")
    from microfacet.cli import main
    assert main(["export", str(corpus("merl/chrome")), "--to", "gltf", "-o", str(tmp_path / "chrome.glb")]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["chrome.glb", "chrome.glb.export.json",
                                                          "chrome.glb.export.md", "chrome.json", "chrome.npz",
                                                          "chrome.png"]
    rep = json.loads((tmp_path / "chrome.glb.export.json").read_text())
    assert rep["source"] == str(tmp_path / "chrome.npz")
    best = json.loads((tmp_path / "chrome.json").read_text())["best"]
    assert rep["model"] == best if best != "tabulated" else rep["model"] != "tabulated"
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "notes.txt").write_text("not a BRDF")
    capsys.readouterr()
    assert main(["export", str(tmp_path / "bad" / "notes.txt"), "--to", "gltf", "-o", str(tmp_path / "bad" / "x")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "notes.txt: unknown measured-BRDF format" in err[0], err
    assert sorted(p.name for p in (tmp_path / "bad").iterdir()) == ["notes.txt"]
