"""*Generate Seats*: a stadium's seats and stands from :mod:`crowd_addon.core.authoring.seats`.

:func:`seat_objects` turns a :class:`~crowd_addon.core.authoring.seats.SeatLayout` into two mesh
objects: "Seats", one vertex per seat with the POINT attributes ``heading`` (FLOAT,
radians about +Z, facing the pitch centre for a character facing -Y) and ``section``,
``tier``, ``row``, ``seat``, ``team`` (INT) and the vertex groups "home" and "away";
"Stands", the terraces and benches with the materials "concrete", "home" and "away"
(:func:`~.looks.plain_material`). The scene records the objects it made there (its
custom properties :data:`SEATS_KEY` and :data:`STANDS_KEY`): making them again in that
scene gives those objects the new meshes, and they keep their names, places,
transforms and the agent sources that use them. Nothing else is taken over: an object
of the user's named "Seats" or "Stands" (or one made before the scene recorded them,
by an older version, or made in another scene) is left as it is, and the new object
is named by Blender ("Seats.001"). The operator (Crowd tab > Agents) fills a
:class:`~crowd_addon.core.authoring.seat_spec.SeatSpec` from its properties and calls it.
"""

from __future__ import annotations

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, \
    IntProperty, IntVectorProperty, StringProperty

from ..core.base.errors import CrowdError
from ..core.authoring.seat_spec import AWAY, HOME, SeatSpec, Tier, Tunnel
from ..core.authoring.seats import generate_seats
from .looks import plain_material

__all__ = ["CLASSES", "SEATS_KEY", "STANDS_KEY", "STAND_COLOURS", "seat_objects",
           "spec_from_operator"]

#: the scene's custom properties that point at the Seats and Stands objects made there
SEATS_KEY, STANDS_KEY = "crowd_seats", "crowd_stands"

#: the Stands' materials (linear RGBA), in the order of the core's face kinds
STAND_COLOURS = {"concrete": (0.55, 0.55, 0.52, 1.0), "home": (0.30, 0.09, 0.09, 1.0),
                 "away": (0.08, 0.13, 0.32, 1.0)}
#: the Seats' point attributes: name -> (the layout's array, Blender type)
SEAT_ATTRIBUTES = {"heading": ("heading", "FLOAT"), "section": ("section", "INT"),
                   "tier": ("tier", "INT"), "row": ("row", "INT"), "seat": ("seat", "INT"),
                   "team": ("team", "INT")}


def _mesh(name, vertices, corners=None, sizes=None):
    """A new mesh of ``vertices`` (V, 3) and faces given flat (``corners``, ``sizes``)."""
    me = bpy.data.meshes.new(name)
    me.vertices.add(len(vertices))
    me.vertices.foreach_set("co", np.ascontiguousarray(vertices, np.float32).ravel())
    if sizes is not None and len(sizes):
        me.loops.add(int(sizes.sum()))
        me.polygons.add(len(sizes))
        me.polygons.foreach_set("loop_start", (np.cumsum(sizes) - sizes).astype(np.int32))
        me.polygons.foreach_set("vertices", np.asarray(corners, np.int32))
        me.update(calc_edges=True)
    else:
        me.update()
    return me


def _put(scene, key, name, mesh, collection):
    """The object ``scene[key]`` points at, when it is still in ``scene``, with its old
    mesh replaced by ``mesh`` (and removed when unused); else a new object ``name``
    (Blender's unique name when that is taken) linked to ``collection`` and recorded
    in ``scene[key]``."""
    obj = scene.get(key)
    if not isinstance(obj, bpy.types.Object) or scene.objects.get(obj.name) != obj:
        obj = bpy.data.objects.new(name, mesh)
        collection.objects.link(obj)
        scene[key] = obj
        return obj
    old = obj.data
    obj.data = mesh
    if old.users == 0:
        bpy.data.meshes.remove(old)
    return obj


def seat_objects(layout, scene, collection, seats_name="Seats", stands_name="Stands",
                 stands=True):
    """The "Seats" (and, with ``stands``, "Stands") objects of ``layout`` in ``scene``
    (see the module docstring); returns ``(seats, stands or None)``. New objects go to
    ``collection``, a collection of ``scene``."""
    me = _mesh(seats_name, layout.position)
    for name, (field, kind) in SEAT_ATTRIBUTES.items():
        me.attributes.new(name, kind, "POINT").data.foreach_set(
            "value", np.ascontiguousarray(getattr(layout, field)))
    me.update()
    seats = _put(scene, SEATS_KEY, seats_name, me, collection)
    for group, team in (("home", HOME), ("away", AWAY)):
        old = seats.vertex_groups.get(group)
        if old is not None:
            seats.vertex_groups.remove(old)
        seats.vertex_groups.new(name=group).add(
            np.flatnonzero(layout.team == team).tolist(), 1.0, "REPLACE")
    if not stands:
        return seats, None
    mesh = layout.stands
    me = _mesh(stands_name, mesh.vertices, mesh.corners, mesh.sizes)
    for name, colour in STAND_COLOURS.items():
        me.materials.append(plain_material(name, colour))
    me.polygons.foreach_set("material_index", mesh.kind.astype(np.int32))
    me.update()
    return seats, _put(scene, STANDS_KEY, stands_name, me, collection)


def _angles(text):
    """Tunnel angles (degrees) from a comma-separated list; a CrowdError naming it."""
    out = []
    for part in text.replace(";", ",").split(","):
        if part.strip():
            try:
                out.append(float(part))
            except ValueError:
                raise CrowdError(f"seat generator: tunnels: {part.strip()!r} is not an angle "
                                 "in degrees (a list such as '90, 270')") from None
    return out


def spec_from_operator(op) -> SeatSpec:
    """The :class:`SeatSpec` the operator's properties describe."""
    tiers = tuple(Tier(rows=op.rows[t], tread=op.tread, riser=op.riser[t],
                       setback=op.setback[t], lift=op.lift[t])
                  for t in range(op.tiers))
    return SeatSpec(
        tiers=tiers, plan=op.plan.lower(), pitch=(op.pitch_length, op.pitch_width),
        margin=(op.margin_end, op.margin_side), corner_radius=op.corner_radius,
        seat_pitch=op.seat_pitch, seat_width=op.seat_width, aisle_every=op.aisle_every,
        aisle_width=op.aisle_width,
        tunnels=tuple(Tunnel(a, op.tunnel_width, op.tunnel_rows) for a in _angles(op.tunnels)),
        away_end=op.away_end.lower(), seats=op.seats or None)


class CROWD_OT_generate_seats(bpy.types.Operator):
    """Make a stadium's seats and stands round the pitch at the world origin: the
    "Seats" object, a point per seat (attributes heading, section, tier, row, seat,
    team; groups home and away) to use as an agent source, and the "Stands" mesh.
    Generating again in the scene gives the objects it made there the new meshes"""

    bl_idname = "crowd.generate_seats"
    bl_label = "Generate Seats"
    bl_options = {"REGISTER", "UNDO"}

    plan: EnumProperty(name="Plan", items=(
        ("RECT", "Four Stands", "Four straight stands joined by rounded corners"),
        ("OVAL", "Oval", "A four-centre oval: end arcs joined by flatter side arcs")),
        default="RECT")
    pitch_length: FloatProperty(name="Pitch Length", default=105.0, min=1.0, unit="LENGTH",
                                description="Length of the pitch, along X")
    pitch_width: FloatProperty(name="Pitch Width", default=68.0, min=1.0, unit="LENGTH",
                               description="Width of the pitch, along Y")
    margin_end: FloatProperty(name="Margin Ends", default=6.5, min=0.0, unit="LENGTH",
                              description="From each goal line to the stand behind it")
    margin_side: FloatProperty(name="Margin Sides", default=6.0, min=0.0, unit="LENGTH",
                               description="From each touchline to the stand beside it")
    corner_radius: FloatProperty(
        name="Corner Radius", default=14.0, min=0.1, unit="LENGTH",
        description="Radius of the corners' front edge (an oval: of its ends)")
    tiers: IntProperty(name="Tiers", default=2, min=1, max=3,
                       description="Tiers of stands, one above the other")
    rows: IntVectorProperty(name="Rows", size=3, default=(32, 36, 20), min=1, max=500,
                            description="Rows of each tier (with a seat count: their "
                                        "proportions, the lower tiers filled first)")
    tread: FloatProperty(name="Tread", default=0.8, min=0.3, max=3.0, unit="LENGTH",
                         description="Depth of a row, front to back")
    riser: FloatVectorProperty(name="Riser", size=3, default=(0.4, 0.45, 0.5), min=0.0,
                               max=1.0, unit="LENGTH",
                               description="How much higher each row is than the one in "
                                           "front, per tier")
    setback: FloatVectorProperty(
        name="Setback", size=3, default=(0.0, -3.2, -3.2), unit="LENGTH",
        description="The first tier: from the stands' front edge; a tier above: from the "
                    "back of the tier below (negative: hanging over its back rows)")
    lift: FloatVectorProperty(
        name="Lift", size=3, default=(1.2, 4.0, 4.0), min=0.0, unit="LENGTH",
        description="The first tier: its front wall; a tier above: its first row over the "
                    "last row of the tier below")
    seat_pitch: FloatProperty(name="Seat Pitch", default=0.5, min=0.2, max=2.0, unit="LENGTH",
                              description="From seat to seat along a row, centre to centre")
    seat_width: FloatProperty(name="Seat Width", default=0.45, min=0.1, max=2.0,
                              unit="LENGTH", description="Width of a seat (at most the pitch)")
    aisle_every: IntProperty(name="Aisle Every", default=24, min=0, max=1000,
                             description="Seats between aisles on a tier's front row (0: "
                                         "aisles only between the stands and the corners)")
    aisle_width: FloatProperty(name="Aisle Width", default=1.2, min=0.0, max=10.0,
                               unit="LENGTH", description="Width of an aisle")
    tunnels: StringProperty(
        name="Tunnels", default="90",
        description="Tunnels through the first tier's front rows, as angles in degrees round "
                    "the pitch centre (0 east, 90 north), separated by commas")
    tunnel_width: FloatProperty(name="Tunnel Width", default=6.0, min=0.1, max=50.0,
                                unit="LENGTH", description="Width of each tunnel")
    tunnel_rows: IntProperty(name="Tunnel Rows", default=8, min=1, max=500,
                             description="Rows each tunnel cuts through")
    away_end: EnumProperty(name="Away End", items=(
        ("EAST", "East", "The stand behind the east goal (+X) holds the away fans"),
        ("WEST", "West", "The stand behind the west goal (-X) holds the away fans"),
        ("NONE", "None", "Every seat is home")), default="EAST")
    seats: IntProperty(name="Seats", default=0, min=0, max=5_000_000,
                       description="Seat count to build for (rows added until it fits, the "
                                   "surplus left empty); 0: the rows as given")
    make_stands: BoolProperty(name="Stands", default=True,
                              description="Also make the Stands mesh")

    def invoke(self, context, _event):
        return context.window_manager.invoke_props_dialog(self, width=420)

    def draw(self, _context):
        layout = self.layout
        layout.use_property_split = True
        col = layout.column(heading="Plan")
        for key in ("plan", "pitch_length", "pitch_width", "margin_end", "margin_side",
                    "corner_radius"):
            col.prop(self, key)
        col = layout.column(heading="Cross-Section")
        col.prop(self, "tiers")
        for key in ("rows", "riser", "setback", "lift"):
            row = col.row(align=True, heading=self.bl_rna.properties[key].name)
            for t in range(self.tiers):
                row.prop(self, key, index=t, text="")
        col.prop(self, "tread")
        col = layout.column(heading="Seats")
        for key in ("seat_pitch", "seat_width", "aisle_every", "aisle_width", "tunnels",
                    "tunnel_width", "tunnel_rows", "away_end", "seats", "make_stands"):
            col.prop(self, key)

    def execute(self, context):
        try:
            layout = generate_seats(spec_from_operator(self))
            collection = context.collection or context.scene.collection
            seat_objects(layout, context.scene, collection, stands=self.make_stands)
        except CrowdError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        rows = " + ".join(str(r) for r in layout.rows)
        self.report({"INFO"}, f"{len(layout):,} seats in {rows} rows, {layout.sections} "
                              f"sections ({int((layout.team == AWAY).sum()):,} away)")
        return {"FINISHED"}


CLASSES = (CROWD_OT_generate_seats,)
