"""Where a shot's crowd comes from, opened the same way for every command: a saved
configuration file or a .blend's scene (with its crowd script's trust, its scene and
its frame range). ``crowd export``, ``crowd snapshot``, ``crowd preview``, ``crowd
plan``, the farm's tasks and the Dask farm's shots all call :meth:`ShotSource.open`.

A configuration is read here; a .blend is opened by :mod:`crowd_addon.blender`
(imported only then: the ``bpy`` module is needed), its crowd script checked before
anything else runs, its Crowd settings baked when the shot's configuration is first
needed. Either way the command gets an object with ``config``, ``frames``, ``scene``
(the Blender scene, None for a configuration), ``crowd(substeps)`` and
``metric_view(settings)`` (the camera the repetition metric is measured through).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from functools import cached_property

from .core.base.errors import CrowdError

__all__ = ["ShotSource", "ConfigShot"]


@dataclass(frozen=True)
class ShotSource:
    """Where a shot's crowd comes from and how it is exported: a configuration file
    (``config``) or a .blend (``blend``, its ``scene``, ``trust_scripts``; neither: the
    .blend open in Blender), with the export's ``agents``, ``layout`` and ``substeps``
    (as ``crowd export``). ``trust_scripts`` holds for the command (or farm task) that
    opens the shot only: a worker that ran a trusted shot trusts nothing after it. A
    .blend whose crowd script would not run stops the shot (ScriptNotTrusted) unless
    ``ignore_scripts``: then the script is left out. ``strict``: a .blend whose bake
    report has warnings stops the shot (``--strict``, BakeWarnings) before anything is
    written."""

    config: str | None = None
    blend: str | None = None
    scene: str | None = None
    trust_scripts: bool = False
    agents: int | None = None
    layout: str = "instanced"
    substeps: int = 1
    ignore_scripts: bool = False
    strict: bool = False

    def __post_init__(self):
        if self.config is not None and self.blend is not None:
            raise CrowdError("a shot comes from one --config or one --blend, not both")
        if self.trust_scripts and self.ignore_scripts:
            raise CrowdError("a shot trusts its crowd script or ignores it, not both")
        if self.config is not None and self.scene is not None:
            raise CrowdError("--scene needs --blend (a configuration has no scenes)")

    def quietly(self):
        """A context in which Blender's own log lines (a .blend's) go to stderr, so a
        command's stdout holds only its summary; nothing for a configuration."""
        if self.config is not None:
            return contextlib.nullcontext()
        from .blender.blend_shot import blender_output_to_stderr
        return blender_output_to_stderr()

    def open(self, frames=None, on_bake=None, frames_needed: bool = True,
             crowd_needed: bool = True, reuse_bake=None, keep_bake=None):
        """The shot: :class:`ConfigShot` or :class:`~crowd_addon.blender.blend_shot.BlendShot`.
        ``frames`` (first, last), or None: a .blend's scene range (a configuration
        needs them when ``frames_needed``); ``on_bake(done, total, message)``: the
        .blend's bake steps and report notes; ``crowd_needed`` False: no crowd will be
        built, so a .blend's crowd script is not checked; ``reuse_bake`` /
        ``keep_bake``: a snapshot folder a .blend's bake is read from / kept in
        (:mod:`crowd_addon.blender.bake_cache`). CrowdError names what is wrong."""
        if self.config is not None:
            if frames is None and frames_needed:
                raise CrowdError("--frames FIRST-LAST is required with --config (a .blend "
                                 "gives its scene's frame range)")
            return ConfigShot(self, frames)
        from .blender.blend_shot import BlendShot
        return BlendShot(self, frames, on_bake, crowd_needed, reuse_bake, keep_bake)


class ConfigShot:
    """A shot of a saved configuration (:func:`~crowd_addon.core.authoring.config_io.
    load_config`): ``config`` (read on first use), ``frames`` (as given), no scene."""

    scene = None

    def __init__(self, source: ShotSource, frames):
        self.source = source
        self.frames = None if frames is None else tuple(int(f) for f in frames)

    @cached_property
    def config(self):
        """The configuration, read on first use."""
        from .core.authoring.config_io import load_config
        return load_config(self.source.config)

    def crowd(self, substeps: int | None = None):
        """The shot's crowd (local poses only: what writers and the GPU preview need)."""
        from .core.shots.crowd import Crowd
        return Crowd(self.config, skinning="gpu",
                     substeps=self.source.substeps if substeps is None else substeps)

    @staticmethod
    def metric_view(settings):
        """``(None, settings)``: a configuration has no camera (the agents are framed)."""
        return None, settings
