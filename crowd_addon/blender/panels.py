"""The "Crowd" tab of the 3D viewport sidebar: characters (each with its armature, body,
LOD meshes, streams and unique animations), agent sources, settings, bake, preview,
USD export, stats."""

import bpy

from ..core.base.errors import CrowdError
from . import preview

__all__ = ["CLASSES"]

_KIND_ICONS = {"CLIP": "ACTION", "BLEND2": "MOD_MASK", "LAYER": "RENDERLAYERS",
               "BLEND_SPACE": "MESH_GRID", "STATE_MACHINE": "NODETREE"}


class CROWD_UL_animations(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, prop):
        row = layout.row(align=True)
        row.prop(item, "name", text="", emboss=False, icon="ARMATURE_DATA")
        made = item.speed_streams * item.copies
        row.label(text=f"{len(item.nodes)} nodes" + (f", {made} streams"
                                                      if prop == "streams" and made > 1
                                                      else ""))
        row.prop(item, "weight", text="")


class CROWD_UL_palettes(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.label(text=item.material or "(no material)", icon="COLOR")
        for i in range(item.count):
            row.prop(item, f"color_{i}", text="")


class CROWD_UL_variants(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.prop(item, "object", text="", icon="OUTLINER_OB_MESH")
        row.prop(item, "weight", text="")


class CROWD_UL_props(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.prop(item, "object", text="", icon="OBJECT_DATA")
        row.label(text=item.bone or (item.object.parent_bone if item.object else "") or "?")
        row.prop(item, "share", text="")


class CROWD_UL_characters(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.prop(item, "name", text="", emboss=False, icon="OUTLINER_OB_ARMATURE")
        row.label(text=item.armature.name if item.armature else "no armature")
        row.prop(item, "weight", text="")


class CROWD_UL_lods(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.label(text=item.name, icon="MESH_DATA")
        row.prop(item, "object", text="")


class CROWD_UL_nodes(bpy.types.UIList):
    def draw_item(self, _context, layout, data, item, _icon, _active, _prop):
        root = data.root or (data.nodes[0].name if len(data.nodes) else "")
        row = layout.row(align=True)
        row.prop(item, "name", text="", emboss=False, icon=_KIND_ICONS[item.kind])
        if item.kind == "CLIP":
            row.label(text=item.action.name if item.action else "no action")
        if item.name == root:
            row.label(text="", icon="HOME")


class CROWD_UL_inputs(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.prop(item, "name", text="", emboss=False)
        row.prop(item, "node", text="")


class CROWD_UL_transitions(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        layout.label(text=f"{item.source} -> {item.target} ({item.duration:g} f)")


class CROWD_UL_sources(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.prop(item, "enabled", text="")
        row.prop(item, "name", text="", emboss=False)
        row.label(text=item.object.name if item.object else "no object")


def _list(layout, list_id, owner, collection, index, pool="STREAMS", rows=3):
    row = layout.row()
    row.template_list(list_id, f"{collection}_{pool}", owner, collection, owner, index,
                      rows=rows)
    col = row.column(align=True)
    for op, icon, extra in (("crowd.item_add", "ADD", {}), ("crowd.item_remove", "REMOVE", {}),
                            ("crowd.item_move", "TRIA_UP", {"step": -1}),
                            ("crowd.item_move", "TRIA_DOWN", {"step": 1})):
        props = col.operator(op, icon=icon, text="")
        props.collection, props.pool = collection, pool
        for k, v in extra.items():
            setattr(props, k, v)
    return row


class _Panel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Crowd"


class CROWD_PT_main(_Panel, bpy.types.Panel):
    bl_label = "Crowd"

    def draw(self, context):
        scene = context.scene
        s = scene.crowd
        layout = self.layout
        layout.use_property_split = True
        pv = preview.check(scene)
        row = layout.row(align=True)
        row.operator("crowd.bake", icon="RENDER_ANIMATION")
        row.operator("crowd.preview_toggle", text="Preview", icon="HIDE_OFF",
                     depress=pv is not None)
        row = layout.row(align=True)
        row.operator("crowd.export_usd", text="Export USD...", icon="EXPORT")
        row.operator("crowd.import_usd", text="Import USD...", icon="IMPORT")
        layout.prop(s, "render_crowd", icon="RESTRICT_RENDER_OFF")
        if pv is None:
            err = preview.last_error(scene)
            if err:
                layout.label(text=err, icon="ERROR")
            return
        box = layout.box()
        c = pv.crowd
        authored = sum(len(ch.streams) for ch in s.characters)
        made = f" (from {authored} authored)" if authored != c.streams.count else ""
        box.label(text=f"{c.agents.count:,} agents, {c.streams.count} streams{made}, "
                       f"{c.uniques.count} uniques, "
                       f"{len(c.config.clips)} clips")
        box.label(text=f"frame {c.frame}: step {pv.step_ms:.2f} ms, draw {pv.draw_ms:.2f} ms")
        box.label(text=snapshot_line(c.snapshots))
        row = box.row(align=True)
        row.operator("crowd.measure_repetition", icon="VIEWZOOM")
        row.prop(s, "repetition_neighbours", text="k")
        if pv.repetition is not None:
            box.label(text=repetition_line(pv.repetition, pv.repetition_seen))
        row = box.row(align=True)
        row.operator("crowd.plan_variety", icon="GRAPH")
        row.prop(s, "plan_budget_mb", text="MB")
        row.prop(s, "plan_max_streams", text="S")
        row.prop(s, "plan_motion_only", text="", icon="ANIM")
        if pv.plan is not None:
            from ..plan_report import summary_lines
            for line in summary_lines(pv.plan):
                box.label(text=line.strip())
            box.operator("crowd.apply_plan", icon="CHECKMARK")
        if s.render_crowd and pv.render_stats is not None:
            r = pv.render_stats
            box.label(text=f"Render Crowd: {r.poses:,} pose meshes for {r.agents:,} agents, "
                           f"{r.ms:.1f} ms a frame")
        for text in (pv.status(), pv.draw_error, pv.render_error):
            if text:
                box.label(text=text, icon="ERROR")


def repetition_line(measured, seen) -> str:
    """The last repetition measurement: its value and what it was measured through."""
    if measured.value is None:
        return f"Repetition at frame {measured.frames[0]}: no neighbours in view ({seen})"
    return (f"Repetition {measured.value:.3f} at frame {measured.frames[0]}: "
            f"{measured.value * 100:.1f} % of neighbour pairs alike, "
            f"{measured.visible[0]:,} agents in {seen}")


def snapshot_line(cache) -> str:
    """What the preview keeps for scrubbing: spacing in use (and asked for), count,
    memory and its cap."""
    if cache is None or cache.max_bytes == 0:
        return "Scrubbing: no snapshots (jumps back replay from the start)"
    mb = 1 << 20
    if not cache.fits:
        return (f"Scrubbing: one snapshot is more than the {cache.max_bytes / mb:,.0f} MB "
                "cap (Preferences): jumps back replay from the start")
    asked = "" if cache.every == cache.requested else f" (asked {cache.requested}, cap reached)"
    return (f"Scrubbing: a snapshot every {cache.every} frames{asked}, {len(cache)} kept, "
            f"{cache.nbytes / mb:,.0f} of {cache.max_bytes / mb:,.0f} MB")


def _active_character(s):
    i = s.active_character_index
    return s.characters[i] if 0 <= i < len(s.characters) else None


def _draw_animation_pool(layout, s, pool):
    char = _active_character(s)
    if char is None:
        layout.label(text="Add a character first (Characters)")
        return
    anims = char.streams if pool == "STREAMS" else char.uniques
    index = "active_stream_index" if pool == "STREAMS" else "active_unique_index"
    _list(layout, "CROWD_UL_animations", char, pool.lower(), index, pool)
    i = getattr(char, index)
    if not 0 <= i < len(anims):
        return
    anim = anims[i]
    layout.prop_search(anim, "root", anim, "nodes")
    if pool == "STREAMS":
        _draw_timing(layout.box(), anim)
    _list(layout, "CROWD_UL_nodes", anim, "nodes", "active_node_index", pool)
    if 0 <= anim.active_node_index < len(anim.nodes):
        _draw_node(layout.box(), anim, anim.nodes[anim.active_node_index], pool)


def _draw_palette(layout, char, pal):
    col = layout.column()
    col.use_property_split = True
    if char.body is not None:
        col.prop_search(pal, "material", char.body, "material_slots")
    else:
        col.prop(pal, "material")
    col.prop(pal, "mode")
    if pal.mode == "ATTRIBUTE":
        col.prop(pal, "attribute")
    col.prop(pal, "count")
    row = layout.row(align=True)
    for i in range(pal.count):
        row.prop(pal, f"color_{i}", text="")


def timing_line(anim) -> str:
    """How many streams a stream's timing variation makes, at which speeds."""
    from .agents import stream_timing
    t = stream_timing(anim)
    try:
        t.check("")
    except CrowdError as e:
        return str(e).lstrip(": ")
    speeds = t.speeds()
    at = f"at {speeds[0]:.3g}x" if speeds.size == 1 else \
        f"at {speeds[0]:.3g}x .. {speeds[-1]:.3g}x"
    copies = f" in {t.copies} copies" if t.copies > 1 else ""
    return f"Makes {t.count} stream{'s' if t.count != 1 else ''} {at}{copies}"


def _draw_timing(layout, anim):
    layout.label(text="Timing Variation")
    col = layout.column(align=True)
    col.prop(anim, "speed_min")
    col.prop(anim, "speed_max")
    layout.prop(anim, "speed_streams")
    layout.prop(anim, "copies")
    layout.label(text=timing_line(anim))


def _draw_node(layout, anim, node, pool):
    layout.use_property_split = True
    layout.prop(node, "kind")
    if node.kind == "CLIP":
        layout.prop(node, "action")
        layout.prop(node, "speed")
        layout.prop(node, "start")
        return
    row = layout.row()
    row.template_list("CROWD_UL_inputs", f"inputs_{pool}", node, "inputs", node,
                      "active_input_index", rows=2)
    col = row.column(align=True)
    for op, icon in (("crowd.item_add", "ADD"), ("crowd.item_remove", "REMOVE")):
        props = col.operator(op, icon=icon, text="")
        props.collection, props.pool = "inputs", pool
    if 0 <= node.active_input_index < len(node.inputs):
        inp = node.inputs[node.active_input_index]
        layout.prop_search(inp, "node", anim, "nodes")
        if node.kind == "BLEND_SPACE":
            layout.prop(inp, "x")
            layout.prop(inp, "y")
    if node.kind in ("BLEND2", "LAYER"):
        layout.prop(node, "weight")
        layout.prop(node, "weight_parameter")
    if node.kind == "LAYER":
        layout.prop(node, "layer_mode")
        layout.prop(node, "mask_source")
        if node.mask_source == "BONES":
            layout.prop(node, "mask_bones")
        elif node.mask_source == "COLLECTION":
            layout.prop(node, "mask_collection")
        if node.layer_mode == "ADDITIVE":
            layout.prop(node, "reference_action")
            layout.prop(node, "reference_frame")
    elif node.kind == "BLEND_SPACE":
        layout.prop(node, "x_parameter")
        layout.prop(node, "y_parameter")
    elif node.kind == "STATE_MACHINE":
        layout.prop_search(node, "initial_state", node, "inputs")
        _list(layout, "CROWD_UL_transitions", node, "transitions",
              "active_transition_index", pool, rows=2)
        if 0 <= node.active_transition_index < len(node.transitions):
            tr = node.transitions[node.active_transition_index]
            for key in ("source", "target", "duration", "trigger", "condition_parameter"):
                layout.prop(tr, key)
            if tr.condition_parameter:
                layout.prop(tr, "condition_op")
                layout.prop(tr, "condition_value")


class CROWD_PT_characters(_Panel, bpy.types.Panel):
    bl_label = "Characters"
    bl_parent_id = "CROWD_PT_main"

    def draw(self, context):
        s = context.scene.crowd
        layout = self.layout
        _list(layout, "CROWD_UL_characters", s, "characters", "active_character_index")
        char = _active_character(s)
        if char is None:
            return
        col = layout.column()
        col.use_property_split = True
        col.prop(char, "armature")
        col.prop(char, "body")
        layout.label(text="LOD Meshes (empty: automatic)")
        _list(layout, "CROWD_UL_lods", char, "lods", "active_lod_index", rows=2)
        layout.label(text="Palettes (a colour per agent for a material of the body)")
        _list(layout, "CROWD_UL_palettes", char, "palettes", "active_palette_index", rows=2)
        if 0 <= char.active_palette_index < len(char.palettes):
            _draw_palette(layout.box(), char, char.palettes[char.active_palette_index])
        layout.label(text="Mesh Variants (other bodies on the same armature)")
        _list(layout, "CROWD_UL_variants", char, "variants", "active_variant_index", rows=2)
        if len(char.variants):
            col = layout.column()
            col.use_property_split = True
            col.prop(char, "body_weight")
            col.prop(char, "variant_mode")
            if char.variant_mode == "ATTRIBUTE":
                col.prop(char, "variant_attribute")
        layout.label(text="Props (objects carried on a bone by a share of agents)")
        _list(layout, "CROWD_UL_props", char, "props", "active_prop_index", rows=2)
        if 0 <= char.active_prop_index < len(char.props):
            prop = char.props[char.active_prop_index]
            col = layout.box().column()
            col.use_property_split = True
            col.prop(prop, "object")
            if char.armature is not None:
                col.prop_search(prop, "bone", char.armature.data, "bones")
            else:
                col.prop(prop, "bone")
            col.prop(prop, "share")


class CROWD_PT_look_rig(_Panel, bpy.types.Panel):
    """The active character's look rig: the bones that turn its head toward a look
    target (docs/show.md, "Look-at")."""

    bl_label = "Look At"
    bl_parent_id = "CROWD_PT_characters"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        s = context.scene.crowd
        char = _active_character(s)
        if char is None:
            return
        col = self.layout.column()
        col.use_property_split = True
        col.prop(char, "look_bones")
        col.prop(char, "look_shares")
        col.prop(char, "look_yaw_limit")
        col.prop(char, "look_pitch_limit")
        forward = s.bl_rna.properties["forward_axis"].enum_items[s.forward_axis].name
        col.label(text=f"The head faces {forward} at rest (Settings > Forward)", icon="INFO")
        if char.armature is not None and char.look_bones.strip():
            bones = char.armature.data.bones
            missing = [b.strip() for b in char.look_bones.split(",")
                       if b.strip() and b.strip() not in bones]
            if missing:
                col.label(text=f"Not bones of {char.armature.name}: {', '.join(missing)}",
                          icon="ERROR")


class CROWD_PT_streams(_Panel, bpy.types.Panel):
    bl_label = "Streams"
    bl_parent_id = "CROWD_PT_characters"

    def draw(self, context):
        _draw_animation_pool(self.layout, context.scene.crowd, "STREAMS")


class CROWD_PT_uniques(_Panel, bpy.types.Panel):
    bl_label = "Unique Animations"
    bl_parent_id = "CROWD_PT_characters"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        _draw_animation_pool(self.layout, context.scene.crowd, "UNIQUES")


class CROWD_PT_agents(_Panel, bpy.types.Panel):
    bl_label = "Agents"
    bl_parent_id = "CROWD_PT_main"

    def draw(self, context):
        s = context.scene.crowd
        layout = self.layout
        _list(layout, "CROWD_UL_sources", s, "agent_sources", "active_source_index")
        layout.operator("crowd.generate_agents", icon="COMMUNITY")
        layout.operator("crowd.generate_seats", icon="MESH_GRID")
        if not 0 <= s.active_source_index < len(s.agent_sources):
            return
        src = s.agent_sources[s.active_source_index]
        col = layout.column()
        col.use_property_split = True
        col.prop(src, "object")
        col.prop(src, "mode")
        if src.mode == "VERTEX_GROUP" and src.object is not None:
            col.prop_search(src, "vertex_group", src.object, "vertex_groups")
        for mode, fields in (("heading_mode", {"FIXED": ("heading",),
                                               "ATTRIBUTE": ("heading_attribute",),
                                               "TARGET": ("heading_target",)}),
                             ("character_mode", {"ATTRIBUTE": ("character_attribute",)}),
                             ("stream_mode", {"ATTRIBUTE": ("stream_attribute",)}),
                             ("offset_mode", {"NORMAL": ("offset_mean", "offset_std"),
                                              "ATTRIBUTE": ("offset_attribute",)}),
                             ("color_mode", {"RANDOM": ("color", "color_variation"),
                                             "ATTRIBUTE": ("color_attribute",)})):
            col.prop(src, mode)
            if mode == "character_mode" and src.character_mode == "FIXED":
                col.prop_search(src, "character_name", s, "characters")
            if mode == "stream_mode" and src.stream_mode == "FIXED":
                _stream_search(col, s, src)
            for key in fields.get(getattr(src, mode), ()):
                col.prop(src, key)
        sub = col.column(align=True)
        sub.prop(src, "scale_min")
        sub.prop(src, "scale_max")


def _stream_search(col, s, src):
    """The One Stream field, searching the streams of the source's character (the
    fixed one, else the active one)."""
    char = s.characters.get(src.character_name) if src.character_mode == "FIXED" else None
    char = char or _active_character(s)
    if char is None:
        col.prop(src, "stream_name")
    else:
        col.prop_search(src, "stream_name", char, "streams")


class CROWD_PT_settings(_Panel, bpy.types.Panel):
    bl_label = "Settings"
    bl_parent_id = "CROWD_PT_main"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        s = context.scene.crowd
        layout = self.layout
        layout.use_property_split = True
        for key in ("max_offset", "transition_slots", "when_full", "seed",
                    "samples_per_frame", "forward_axis", "lod_near", "lod_far", "lod_cards"):
            layout.prop(s, key)
        row = layout.row()
        row.enabled = s.lod_cards
        row.prop(s, "lod_card")
        row = layout.row()
        row.enabled = s.lod_cards
        row.prop(s, "lod_joined")


CLASSES = (CROWD_UL_characters, CROWD_UL_lods, CROWD_UL_palettes, CROWD_UL_variants,
           CROWD_UL_props, CROWD_UL_animations,
           CROWD_UL_nodes,
           CROWD_UL_inputs, CROWD_UL_transitions, CROWD_UL_sources, CROWD_PT_main,
           CROWD_PT_characters, CROWD_PT_look_rig, CROWD_PT_streams, CROWD_PT_uniques,
           CROWD_PT_agents,
           CROWD_PT_settings)
