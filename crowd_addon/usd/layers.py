"""Sdf-level authoring helpers (fast: no stage, no composition while writing).

Every layer the exporter writes gets the same stage metadata: Z up, metres
(``metersPerUnit = 1``), ``timeCodesPerSecond = framesPerSecond =`` the crowd's fps,
so that references and sublayers never rescale time.
"""

from __future__ import annotations

from pxr import Sdf

__all__ = ["new_layer", "layer_from_text", "define", "attribute", "relationship", "apply_api", "connect"]

_API_OPS = {}


def new_layer(fmt: str, fps: float, start: float, end: float, default_prim: str | None = None,
              comment: str = "") -> Sdf.Layer:
    """An anonymous layer of format ``fmt`` (``"usdc"`` or ``"usda"``) with the shared
    stage metadata and time range ``start .. end`` (frames)."""
    return _stamp(Sdf.Layer.CreateAnonymous(f".{fmt}"), fps, start, end, default_prim,
                  comment)


def layer_from_text(text: str, fmt: str, fps: float, start: float, end: float,
                    comment: str = "") -> Sdf.Layer:
    """An anonymous layer of format ``fmt`` holding ``text`` (usda) as read by USD's
    parser, with the shared stage metadata (:func:`new_layer`)."""
    layer = Sdf.Layer.CreateAnonymous(f".{fmt}")
    if not layer.ImportFromString(text):
        raise RuntimeError("USD could not read the text layer it was given")
    return _stamp(layer, fps, start, end, None, comment)


def _stamp(layer, fps, start, end, default_prim, comment) -> Sdf.Layer:
    layer.timeCodesPerSecond = float(fps)
    layer.framesPerSecond = float(fps)
    layer.startTimeCode = float(start)
    layer.endTimeCode = float(end)
    root = layer.pseudoRoot
    root.SetInfo("upAxis", "Z")
    root.SetInfo("metersPerUnit", 1.0)
    if default_prim:
        layer.defaultPrim = default_prim
    if comment:
        layer.comment = comment
    return layer


def define(parent, name: str, type_name: str = "") -> Sdf.PrimSpec:
    """``def <type_name> "<name>"`` under ``parent`` (a layer or a prim spec)."""
    return Sdf.PrimSpec(parent, name, Sdf.SpecifierDef, type_name)


def attribute(prim: Sdf.PrimSpec, name: str, type_name, value=None, uniform: bool = False,
              **info) -> Sdf.AttributeSpec:
    """An attribute spec with an optional default value and metadata ``info``
    (e.g. ``interpolation="vertex"``, ``elementSize=4``)."""
    spec = Sdf.AttributeSpec(prim, name, type_name,
                             Sdf.VariabilityUniform if uniform else Sdf.VariabilityVarying)
    if value is not None:
        spec.default = value
    for key, v in info.items():
        spec.SetInfo(key, v)
    return spec


def relationship(prim: Sdf.PrimSpec, name: str, target) -> Sdf.RelationshipSpec:
    """A relationship with one explicit target path."""
    spec = Sdf.RelationshipSpec(prim, name, False)
    spec.targetPathList.explicitItems = [target if isinstance(target, Sdf.Path)
                                         else Sdf.Path(str(target))]
    return spec


def apply_api(prim: Sdf.PrimSpec, schema: str) -> None:
    """Add ``schema`` to the prim's ``prepend apiSchemas`` (one shared list op per list
    of schemas, so 65k agents do not build 65k of them)."""
    items = tuple(prim.GetInfo("apiSchemas").prependedItems) if prim.HasInfo("apiSchemas") \
        else ()
    if schema in items:
        return
    items += (schema,)
    op = _API_OPS.get(items)
    if op is None:
        op = _API_OPS[items] = Sdf.TokenListOp.Create(prependedItems=list(items))
    prim.SetInfo("apiSchemas", op)


def connect(attr: Sdf.AttributeSpec, source: Sdf.AttributeSpec) -> None:
    """``attr`` reads ``source`` (a shading connection)."""
    attr.connectionPathList.explicitItems = [source.path]
