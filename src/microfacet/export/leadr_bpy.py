"""Blender (Cycles) scene of a LEADR level: a textured plane seen from above, built in ``bpy``.

Standalone on purpose (no ``microfacet`` import; ``bpy`` only inside the functions that
build): Blender 4.5 as a Python module pins ``numpy<2``, so
:func:`microfacet.export.leadr_consumers.leadr_blend` runs this file with the interpreter that
has ``bpy`` (:func:`microfacet.export.blender.blender_python`), giving it a JSON scene
description (``python leadr_bpy.py --scene scene.json [--blend OUT.blend] [--exr OUT.exr]``).

The material (:func:`build_material`) is a Principled BSDF (``distribution = GGX``, never the
boosted ``MULTI_GGX``) fed by three Image Texture nodes (``Non-Color``, ``REPEAT``, packed in
the ``.blend``) on the plane's UV map ``UVMap`` scaled by a Mapping node:

* ``normal``: a Normal Map node (tangent space, strength 1) into ``Normal``;
* ``roughness``: its R channel into ``Roughness`` (``r = (alpha1 alpha2)^(1/4)``);
* ``anisotropy``: B into ``Anisotropic`` (``a = (1 - alpha2/alpha1)/0.9``), and R, G the doubled
  angle ``(cos 2 phi, sin 2 phi)`` encoded ``(v + 1)/2``, into ``Anisotropic Rotation =
  atan2(2G - 1, 2R - 1) / (4 pi)`` (Math nodes): the axis of the ellipse without the
  ``phi``/``phi + pi`` seam, so that bilinear filtering between texels never flips it;
* a Tangent node (UV Map ``UVMap``) into ``Tangent``: Cycles turns it by the rotation about the
  normal-mapped normal and orthogonalises it against that normal.

The scene (:func:`build_scene`): the plane ``[-1, 1]^2`` (UV ``(x + 1)/2, (y + 1)/2`` times
``tiles``), an orthographic camera looking down ``-z`` over exactly that square, a sun of
irradiance 1 (angle 0), no world light, no bounces, box pixel filter of width 1 (each sample a
uniform point of the pixel: ``spp`` samples supersample the pixel), view transform Standard,
Cycles on the CPU.
"""
from __future__ import annotations

import argparse
import json
import math
import sys

__all__ = ["build_material", "build_scene", "main"]


def _image_node(bpy, nt, path: str, interpolation: str, mapping):
    img = bpy.data.images.load(path, check_existing=False)
    img.colorspace_settings.name = "Non-Color"
    img.alpha_mode = "NONE"
    img.pack()
    node = nt.nodes.new("ShaderNodeTexImage")
    node.image = img
    node.interpolation = interpolation
    node.extension = "REPEAT"
    nt.links.new(mapping.outputs["Vector"], node.inputs["Vector"])
    return node


def build_material(bpy, scene: dict):
    """The LEADR material of a scene description (module docstring): ``scene["textures"]``
    names the ``normal``, ``roughness`` and ``anisotropy`` PNGs, ``scene["tiles"]`` the UV
    scale, ``scene["interpolation"]`` (``Linear`` or ``Closest``), ``base_color``, ``metallic``.

    Parameters
    ----------
    bpy : module
        Blender's ``bpy`` (4.5).
    scene : dict
        The scene description.

    Returns
    -------
    bpy.types.Material
    """
    mat = bpy.data.materials.new(scene.get("name", "leadr"))
    mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    bsdf = nt.nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.distribution = "GGX"
    bsdf.inputs["Base Color"].default_value = list(scene.get("base_color", [0.9, 0.9, 0.9])) + [1.0]
    bsdf.inputs["Metallic"].default_value = float(scene.get("metallic", 1.0))
    bsdf.inputs["Specular Tint"].default_value = (1.0, 1.0, 1.0, 1.0)
    uv = nt.nodes.new("ShaderNodeUVMap")
    uv.uv_map = "UVMap"
    mapping = nt.nodes.new("ShaderNodeMapping")
    mapping.vector_type = "POINT"
    t = float(scene.get("tiles", 1.0))
    mapping.inputs["Scale"].default_value = (t, t, 1.0)
    nt.links.new(uv.outputs["UV"], mapping.inputs["Vector"])
    interp = scene.get("interpolation", "Linear")
    tex = {k: _image_node(bpy, nt, scene["textures"][k], interp, mapping)
           for k in ("normal", "roughness", "anisotropy")}
    for k, node in tex.items():
        node.name = node.label = f"leadr {k}"
    nmap = nt.nodes.new("ShaderNodeNormalMap")
    nmap.space = "TANGENT"
    nmap.uv_map = "UVMap"
    nmap.inputs["Strength"].default_value = 1.0
    nt.links.new(tex["normal"].outputs["Color"], nmap.inputs["Color"])
    nt.links.new(nmap.outputs["Normal"], bsdf.inputs["Normal"])
    sep_r = nt.nodes.new("ShaderNodeSeparateColor")
    nt.links.new(tex["roughness"].outputs["Color"], sep_r.inputs["Color"])
    nt.links.new(sep_r.outputs["Red"], bsdf.inputs["Roughness"])
    sep = nt.nodes.new("ShaderNodeSeparateColor")
    nt.links.new(tex["anisotropy"].outputs["Color"], sep.inputs["Color"])
    nt.links.new(sep.outputs["Blue"], bsdf.inputs["Anisotropic"])
    c2, s2 = (nt.nodes.new("ShaderNodeMath") for _ in range(2))
    for node, channel in ((c2, "Red"), (s2, "Green")):
        node.operation = "MULTIPLY_ADD"                      # 2 v - 1
        nt.links.new(sep.outputs[channel], node.inputs[0])
        node.inputs[1].default_value, node.inputs[2].default_value = 2.0, -1.0
    at = nt.nodes.new("ShaderNodeMath")
    at.operation = "ARCTAN2"                                 # atan2(first, second)
    nt.links.new(s2.outputs[0], at.inputs[0])
    nt.links.new(c2.outputs[0], at.inputs[1])
    rot = nt.nodes.new("ShaderNodeMath")
    rot.operation = "DIVIDE"
    nt.links.new(at.outputs[0], rot.inputs[0])
    rot.inputs[1].default_value = 4.0 * math.pi
    nt.links.new(rot.outputs[0], bsdf.inputs["Anisotropic Rotation"])
    tangent = nt.nodes.new("ShaderNodeTangent")
    tangent.direction_type = "UV_MAP"
    tangent.uv_map = "UVMap"
    nt.links.new(tangent.outputs["Tangent"], bsdf.inputs["Tangent"])
    nt.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    for i, node in enumerate(nt.nodes):
        node.location = (-300 * (i % 4), -250 * (i // 4))
    mat["microfacet_leadr"] = json.dumps({k: v for k, v in scene.items() if k != "textures"})
    return mat


def _plane(bpy):
    import bmesh
    mesh = bpy.data.meshes.new("plane")
    bm = bmesh.new()
    verts = [bm.verts.new(v) for v in ((-1.0, -1.0, 0.0), (1.0, -1.0, 0.0), (1.0, 1.0, 0.0), (-1.0, 1.0, 0.0))]
    face = bm.faces.new(verts)
    face.smooth = True
    uv = bm.loops.layers.uv.new("UVMap")
    for loop in face.loops:
        x, y, _ = loop.vert.co
        loop[uv].uv = ((x + 1.0) / 2.0, (y + 1.0) / 2.0)
    bm.to_mesh(mesh)
    bm.free()
    return mesh


def build_scene(bpy, mat, scene: dict):
    """Set the current scene to the LEADR plane (module docstring) with ``mat``:
    ``scene["size"]`` pixels square, ``spp`` samples, sun from ``light`` (direction toward it),
    ``threads`` CPU threads, ``seed``.

    Parameters
    ----------
    bpy : module
        Blender's ``bpy``.
    mat : bpy.types.Material
        The plane's material (:func:`build_material`).
    scene : dict
        The scene description.

    Returns
    -------
    bpy.types.Scene
    """
    from mathutils import Vector
    sc = bpy.context.scene
    for ob in list(sc.objects):
        bpy.data.objects.remove(ob, do_unlink=True)
    plane = bpy.data.objects.new("plane", _plane(bpy))
    plane.data.materials.append(mat)
    sc.collection.objects.link(plane)
    cam = bpy.data.cameras.new("camera")
    cam.type = "ORTHO"
    cam.ortho_scale = 2.0
    cam_ob = bpy.data.objects.new("camera", cam)
    cam_ob.location = (0.0, 0.0, 5.0)
    sc.collection.objects.link(cam_ob)
    sc.camera = cam_ob
    sun = bpy.data.lights.new("sun", "SUN")
    sun.energy = 1.0
    sun.angle = 0.0
    sun_ob = bpy.data.objects.new("sun", sun)
    sun_ob.rotation_euler = Vector(scene.get("light", (0.0, 0.0, 1.0))).normalized().to_track_quat("Z", "Y").to_euler()
    sc.collection.objects.link(sun_ob)
    world = sc.world or bpy.data.worlds.new("world")
    sc.world = world
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = int(scene.get("spp", 64))
    sc.cycles.use_adaptive_sampling = False
    sc.cycles.use_denoising = False
    sc.cycles.pixel_filter_type = "BOX"
    sc.cycles.filter_width = 1.0
    sc.cycles.max_bounces = 0
    sc.cycles.seed = int(scene.get("seed", 0))
    sc.render.resolution_x = sc.render.resolution_y = int(scene.get("size", 96))
    sc.render.resolution_percentage = 100
    sc.render.film_transparent = True
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    sc.render.threads_mode = "FIXED"
    sc.render.threads = int(scene.get("threads", 1))
    return sc


def main(argv=None) -> int:
    """Command line of the interpreter that has ``bpy``: build the scene of ``--scene`` (JSON),
    save ``--blend``, render ``--exr`` (32-bit float OpenEXR).

    Parameters
    ----------
    argv : list of str, optional
        The arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        0.
    """
    p = argparse.ArgumentParser(description="Build the LEADR plane in Blender (bpy) and save or render it")
    p.add_argument("--scene", required=True, help="scene description JSON")
    p.add_argument("--blend", help="write this .blend")
    p.add_argument("--exr", help="render into this EXR")
    a = p.parse_args(argv)
    with open(a.scene) as f:
        scene = json.load(f)
    import bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = build_scene(bpy, build_material(bpy, scene), scene)
    if a.blend:
        bpy.ops.wm.save_as_mainfile(filepath=a.blend, compress=True)
    if a.exr:
        sc.render.image_settings.file_format = "OPEN_EXR"
        sc.render.image_settings.color_depth = "32"
        sc.render.filepath = a.exr
        bpy.ops.render.render(write_still=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
