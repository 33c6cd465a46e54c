"""A character's UV map and materials, from the .blend to the USD and back into Blender.

The body's UV map is made checkable on its own: every loop's UV is its vertex's (x, y).
It wears two materials, a Principled BSDF with a red base colour and one whose base
colour is an image texture. The oracle at the end is Blender's own USD importer: the
imported agent shows the same UV map (still each vertex's (x, y)), the same base
colour, and a texture that is the same image, copied beside the export.
"""

import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(__file__))
import crowd_scene as cs  # noqa: E402

from crowd_addon.blender import preview  # noqa: E402
from crowd_addon.blender.armature import proxy_mesh_from_object  # noqa: E402

RED = (0.7, 0.1, 0.1, 1.0)


extension = cs.extension_fixture()


def principled(name, color=None, image=None):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    if color is not None:
        bsdf.inputs["Base Color"].default_value = color
    if image is not None:
        tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
        tex.image = image
        mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    return mat


@pytest.fixture
def dressed(tmp_path):
    """A scene whose one character wears a UV map and two materials."""
    preview.stop_all()
    scene = cs.reset()
    scene.frame_end = 6
    rig = cs.make_armature()
    walk = cs.make_action(rig, "walk", seed=1)
    body = cs.make_proxy(rig)
    me = body.data
    uv = me.uv_layers.new(name="UVMap")
    co = np.array([v.co[:] for v in me.vertices])
    vert = np.array([lp.vertex_index for lp in me.loops])
    uv.uv.foreach_set("vector", co[vert, :2].astype(np.float32).ravel())
    image = bpy.data.images.new("skin", 4, 4)
    image.filepath_raw = str(tmp_path / "skin.png")
    image.file_format = "PNG"
    image.save()
    for mat in (principled("Shirt", RED), principled("Skin", image=image)):
        me.materials.append(mat)
    for poly in me.polygons:
        poly.material_index = poly.index % 2
    s = scene.crowd
    s.max_offset = 4
    cs.add_stream(cs.add_character(s, rig, body), "walk", walk)
    src = s.agent_sources.add()
    src.name, src.object = "seats", cs.make_seats(3, 2)
    return scene, rig, body, tmp_path / "skin.png"


def test_the_proxy_mesh_takes_the_uv_map_and_the_materials(dressed):
    _, rig, body, png = dressed
    mesh = proxy_mesh_from_object(body, rig)
    corners = mesh.positions[mesh.triangles.astype(np.int64)]        # (T, 3, 3)
    np.testing.assert_allclose(mesh.uvs, corners[:, :, :2], atol=1e-6)
    assert [k.name for k in mesh.looks] == ["Shirt", "Skin"]
    assert mesh.looks[0].color == pytest.approx(RED) and not mesh.looks[0].texture
    assert mesh.looks[1].texture == str(png)
    # each triangle wears its polygon's material (quads: two triangles each)
    polygon = np.array([lt.polygon_index for lt in body.data.loop_triangles])
    assert (mesh.material == polygon % 2).all()


def test_blenders_importer_shows_the_same_uvs_and_materials(dressed, tmp_path):
    scene, _, _, png = dressed
    out = tmp_path / "export" / "looks.usdc"
    os.makedirs(out.parent)
    assert bpy.ops.crowd.export_usd(filepath=str(out), usd_layout="blender") == {"FINISHED"}
    copied = out.parent / "looks.layers" / "v1" / "textures" / "skin.png"
    assert copied.read_bytes() == png.read_bytes()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=str(out))
    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    assert len(meshes) == 6
    for obj in meshes[:2]:
        me = obj.data
        co = np.array([v.co[:] for v in me.vertices])
        vert = np.array([lp.vertex_index for lp in me.loops])
        uv = np.empty(len(me.loops) * 2, np.float32)
        me.uv_layers.active.uv.foreach_get("vector", uv)
        np.testing.assert_allclose(uv.reshape(-1, 2), co[vert, :2], atol=1e-6)
        names = [m.name.split(".")[0] for m in me.materials]
        assert names == ["Shirt", "Skin"]
        shirt, skin = (m.node_tree.nodes["Principled BSDF"] for m in me.materials)
        assert tuple(shirt.inputs["Base Color"].default_value) == pytest.approx(RED, abs=1e-6)
        (link,) = skin.inputs["Base Color"].links
        assert link.from_node.type == "TEX_IMAGE"
        assert os.path.realpath(bpy.path.abspath(link.from_node.image.filepath)) == \
            os.path.realpath(copied)
        polygon_material = np.array([p.material_index for p in me.polygons])
        assert set(polygon_material.tolist()) == {0, 1}


def test_a_plain_material_looks_the_same_in_every_engine_and_in_the_crowd():
    """``plain_material``: the viewport colour (Workbench), the Principled BSDF's base
    colour (EEVEE, Cycles) and the crowd's look all hold the colour. Before it, the
    demo set the viewport colour alone, which Blender 5's default node tree ignores:
    its props and stadium rendered in that tree's grey, and the preview drew them so."""
    from crowd_addon.blender.looks import _look, plain_material, principled as bsdf_of
    cs.reset()
    pole = (0.30, 0.20, 0.12, 1.0)
    mat = plain_material("pole", pole)
    np.testing.assert_allclose(mat.diffuse_color, pole, atol=1e-6)
    np.testing.assert_allclose(bsdf_of(mat).inputs["Base Color"].default_value, pole,
                               atol=1e-6)
    np.testing.assert_allclose(_look(mat).color, pole, atol=1e-6)
    assert plain_material("pole", (1.0, 0.0, 0.0, 1.0)) == mat        # reused, recoloured
    np.testing.assert_allclose(_look(mat).color, (1.0, 0.0, 0.0, 1.0), atol=1e-6)


@pytest.mark.parametrize("materials", ["MAKE_UNIQUE", "REFERENCE_EXISTING"])
def test_blenders_importer_shows_each_agents_colours(dressed, tmp_path, materials):
    """A grey shirt (agents' tints) and a palette on the skin, exported in the
    ``blender`` layout and imported by Blender's own USD importer: each look's material
    reads an attribute (the Attribute node the importer makes of the primvar reader)
    that each imported agent mesh holds, with that agent's colour as the crowd has it
    (the tint rule of ``core.mesh.tinted``, the palette colour). Before, the layout
    wrote the looks' own colours: every agent the same grey shirt and the same skin.
    The importer's default makes each agent its own copy of each material; with
    *Reference Existing* all the agents share one per look, still in their colours.
    Blender 4.2's importer makes nothing of a primvar reader (the look comes in with
    the default base colour): checked there as a control, the attributes still
    arriving, so a change in that importer shows here."""
    from crowd_addon.blender.scene_config import config_from_scene
    from crowd_addon.core.meshes.mesh import tinted
    from crowd_addon.usd.character import palette_primvar, tint_primvar
    scene = dressed[0]
    grey = (0.9, 0.9, 0.9, 1.0)
    bpy.data.materials["Shirt"].node_tree.nodes["Principled BSDF"].inputs[
        "Base Color"].default_value = grey
    pal = scene.crowd.characters[0].palettes.add()
    pal.material, pal.mode, pal.count = "Skin", "RANDOM", 3
    cfg = config_from_scene(scene)
    want = {"Shirt": (tint_primvar("Shirt"), tinted(grey[:3], cfg.agent_color)),
            "Skin": (palette_primvar(0), cfg.agent_palette[:, 0])}
    assert len({tuple(c) for c in want["Shirt"][1].round(4)}) > 1   # the agents differ
    out = tmp_path / "export" / "looks.usdc"
    os.makedirs(out.parent)
    assert bpy.ops.crowd.export_usd(filepath=str(out), usd_layout="blender") == {"FINISHED"}
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=str(out), mtl_name_collision_mode=materials)
    if materials == "REFERENCE_EXISTING":
        assert sorted(m.name for m in bpy.data.materials) == ["Shirt", "Skin"]
    reads = bpy.app.version >= (4, 5, 0)
    for mat in bpy.data.materials:              # every copy of each look
        attribute = want[mat.name.split(".")[0]][0]
        links = mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].links
        assert len(links) == reads, mat.name
        if reads:
            assert links[0].from_node.type == "ATTRIBUTE", mat.name
            assert links[0].from_node.attribute_name == attribute, mat.name
    seen = 0
    for obj in bpy.data.objects:
        if obj.type != "MESH":
            continue
        agent = next(int(p.name.split("_")[1]) for p in _ancestors(obj)
                     if p.name.startswith("agent_"))
        for look, (attribute, colours) in want.items():
            values = obj.data.attributes[attribute]
            got = np.empty(len(values.data) * 4, np.float32)
            values.data.foreach_get("color", got)
            np.testing.assert_allclose(got.reshape(-1, 4)[:, :3],
                                       np.broadcast_to(colours[agent], (len(values.data), 3)),
                                       atol=1e-6, err_msg=f"{obj.name} {look}")
        seen += 1
    assert seen == 6


def _ancestors(obj):
    while obj is not None:
        yield obj
        obj = obj.parent
