"""Public Python API for simulation developers: events in, transitions and triggers out.

The same :class:`CrowdHandle` works in two places:

* headless, around a core :class:`~crowd_addon.core.Crowd` you step yourself::

      from crowd_addon import api
      sim = api.wrap(crowd)
      sim.on_event("footstep", lambda name, frame, agents: print(name, frame, agents))
      sim.advance_to(100)

* in Blender, around the crowd the viewport preview runs for a scene (the handle
  outlives re-bakes, undo and reloads of the same file: callbacks and parameters move
  to each new crowd; opening another file, or File > New, drops every scene's
  handle; a previewed scene's handle follows the scene's renames)::

      api.on_event("cheer", react)            # the context scene's crowd
      api.transition_to_unique([3, 4], "wave", duration=6)
      api.set_trigger("fans", "stand_up")

Callbacks receive ``(event name, frame, agent ids)``: one call per (event, frame) with
all agents that crossed the tag on that frame (``int64`` array, ascending). A callback
that raises is logged and kept in :attr:`CrowdHandle.errors` (``CallbackError`` records);
the crowd goes on. The handle's callbacks live in one core ``EventDispatcher``, the same
class every crowd delivers its tags through.
Frames re-simulated only to rebuild history after a backwards jump
(:meth:`CrowdHandle.advance_to`) are not reported again.
"""

from __future__ import annotations

import logging

import numpy as np

from .core.base.errors import CrowdError
from .core.runtime.events import EventDispatcher
from .core.shots.driver import FrameDriver

__all__ = ["CrowdHandle", "wrap", "scene_crowd", "on_event", "off", "transition_to_streamed",
           "transition_to_unique", "set_trigger", "set_parameter", "detach_all",
           "forget_scenes", "rename_scene"]

log = logging.getLogger("crowd_addon.api")


class CrowdHandle:
    """Callbacks, transition requests and parameters for a crowd that may come and go.

    ``crowd`` is the core crowd now attached (``None`` until one is); requests need
    one, callbacks and parameters do not (they apply to every crowd attached later).
    """

    def __init__(self, label="crowd"):
        self.label = label
        self.crowd = None
        self._callbacks = EventDispatcher(label)
        self._params = {}
        self._mute_before = None

    # ------------------------------------------------------------------- crowds
    def attach(self, crowd):
        """Use ``crowd`` from now on (the previous one no longer reports events);
        parameters set earlier are applied to it."""
        if self.crowd is crowd:
            return
        self.detach()
        self.crowd = crowd
        self._token = crowd.on_event("*", self._dispatch)
        for (target, name), value in self._params.items():
            try:
                crowd.set_parameter(target, name, value)
            except CrowdError as e:
                log.warning("%s: parameter %r of %r not applied: %s", self.label, name,
                            target, e)

    def detach(self):
        if self.crowd is not None:
            self.crowd.events.off(self._token)
        self.crowd = None

    def _need(self):
        if self.crowd is None:
            raise CrowdError(f"{self.label}: no crowd is running (bake the crowd or start "
                             "the preview first)")
        return self.crowd

    # ------------------------------------------------------------------- events
    def on_event(self, name: str, fn) -> int:
        """Call ``fn(name, frame, agent_ids)`` when event tag ``name`` fires (``"*"``:
        every tag). Returns a handle for :meth:`off`."""
        if not callable(fn):
            raise CrowdError(f"{self.label}: callback for event {name!r} is not callable")
        return self._callbacks.on(name, fn)

    def off(self, handle: int) -> None:
        """Remove a callback registered with :meth:`on_event`."""
        self._callbacks.off(handle)

    @property
    def errors(self):
        """The newest ``CallbackError`` records of callbacks that raised (see
        ``core.events.EventDispatcher``: older ones are counted, not kept)."""
        return self._callbacks.errors

    def _dispatch(self, name, frame, agents):
        if self._mute_before is None or frame >= self._mute_before:
            self._callbacks.dispatch(frame, name, agents)

    # ---------------------------------------------------------------- stepping
    def advance_to(self, frame: int):
        """Step the crowd to ``frame``. Going backwards re-simulates from the start
        (deterministic) or from the nearest snapshot the crowd keeps; the frames
        replayed before ``frame`` report no events."""
        from .core.base.bounds import whole_frame
        crowd = self._need()
        frame = whole_frame(frame, "advance_to")      # CrowdError, as Crowd.advance_to
        if frame < crowd.frame or crowd.jump_snapshot(frame) is not None:
            self._mute_before = frame
        try:
            FrameDriver(crowd).seek(frame)
        finally:
            self._mute_before = None
        return crowd.frame

    def step(self):
        """Advance one frame (headless use); returns the core ``StepReport``."""
        return FrameDriver(self._need()).step()

    @property
    def frame(self) -> int:
        return self._need().frame

    # -------------------------------------------------------------- simulation
    def transition_to_streamed(self, agents, stream, duration=8, offset=None,
                               when_full=None):
        """Blend ``agents`` (ids) to ``stream`` (name or index) at ``offset`` (default
        each agent's own) over ``duration`` frames; returns the core
        ``TransitionResult`` (started, queued and cut agents)."""
        return self._need().transition_to_streamed(np.asarray(agents), stream, duration,
                                                   offset, when_full)

    def transition_to_unique(self, agents, unique, duration=8, restart=True,
                             when_full=None):
        """Blend ``agents`` to unique animation ``unique`` (name or index)."""
        return self._need().transition_to_unique(np.asarray(agents), unique, duration,
                                                 restart, when_full)

    def set_trigger(self, target, name: str):
        """Set trigger ``name`` on a stream or unique (name or stream index); its state
        machines see it on the next frame."""
        self._need().set_trigger(target, name)

    def set_parameter(self, target, name: str, value: float):
        """Set controller parameter ``name`` of a stream or unique; remembered and
        applied again to crowds attached later."""
        crowd = self.crowd
        if crowd is not None:
            crowd.set_parameter(target, name, value)
        else:
            value = float(value)
            if not np.isfinite(value):
                raise CrowdError(f"parameter {name!r}: value must be finite, got {value!r}")
        self._params[(target, str(name))] = float(value)

    def state_of(self, target) -> list:
        """Current state names of the state machines in a stream's or unique's tree."""
        return self._need().state_of(target)


def wrap(crowd) -> CrowdHandle:
    """A handle around a headless core ``Crowd``."""
    handle = CrowdHandle("crowd")
    handle.attach(crowd)
    return handle


# ------------------------------------------------------------------- in Blender
_SCENES: dict = {}
#: ``() -> scene name`` of the context scene, and ``() -> None`` that brings the handles'
#: names up to date with renames; the extension installs them when it registers
#: (:func:`set_context_scene`), so this module needs no ``bpy``.
_context_scene = None
_follow_renames = None


def set_context_scene(fn, follow_renames=None) -> None:
    """Install ``fn() -> str | None`` (the context scene's name) used when a call names
    no scene, and ``follow_renames()`` run before any scene's handle is looked up (it
    calls :func:`rename_scene` for scenes renamed since); None removes them."""
    global _context_scene, _follow_renames
    _context_scene, _follow_renames = fn, follow_renames


def _scene_name(scene) -> str:
    if isinstance(scene, str):
        return scene
    if scene is not None:
        return scene.name
    if _context_scene is None:
        raise CrowdError("no scene given and no Blender context (the extension is not "
                         "registered); use api.wrap(crowd) outside Blender")
    name = _context_scene()
    if name is None:
        raise CrowdError("no scene given and the context has none")
    return name


def scene_crowd(scene=None) -> CrowdHandle:
    """The handle of a scene's crowd (``scene``: a Scene, a scene name, or None for
    the context scene), created on first use. The viewport preview attaches each
    crowd it builds to it."""
    if _follow_renames is not None:
        _follow_renames()
    name = _scene_name(scene)
    handle = _SCENES.get(name)
    if handle is None:
        handle = _SCENES[name] = CrowdHandle(f"scene {name!r}")
    return handle


def detach_all() -> None:
    """Detach every scene's crowd (the extension does this when it unregisters);
    callbacks and parameters stay for the next crowd."""
    for handle in _SCENES.values():
        handle.detach()


def forget_scenes() -> None:
    """Drop every scene's handle, its callbacks and parameters with it (the extension
    does this before another file, or a new one, is loaded: they were for this file's
    scenes)."""
    detach_all()
    _SCENES.clear()


def rename_scene(old: str, new: str) -> None:
    """Scene ``old`` is now called ``new``: its handle (callbacks, parameters, crowd)
    goes with it. When ``new`` has a handle already (callbacks registered under that
    name), that one stays and takes the crowd over; ``old``'s stays under ``old``."""
    handle = _SCENES.pop(old, None)
    if handle is None:
        return
    there = _SCENES.get(new)
    if there is None:
        handle.label = f"scene {new!r}"
        _SCENES[new] = handle
        return
    _SCENES[old] = handle
    crowd = handle.crowd
    handle.detach()
    if crowd is not None:
        there.attach(crowd)


def on_event(name, fn, scene=None) -> int:
    return scene_crowd(scene).on_event(name, fn)


def off(handle, scene=None) -> None:
    scene_crowd(scene).off(handle)


def transition_to_streamed(agents, stream, duration=8, offset=None, when_full=None,
                           scene=None):
    return scene_crowd(scene).transition_to_streamed(agents, stream, duration, offset,
                                                     when_full)


def transition_to_unique(agents, unique, duration=8, restart=True, when_full=None,
                         scene=None):
    return scene_crowd(scene).transition_to_unique(agents, unique, duration, restart,
                                                   when_full)


def set_trigger(target, name, scene=None) -> None:
    scene_crowd(scene).set_trigger(target, name)


def set_parameter(target, name, value, scene=None) -> None:
    scene_crowd(scene).set_parameter(target, name, value)


for _f in (on_event, off, transition_to_streamed, transition_to_unique, set_trigger,
           set_parameter):
    _f.__doc__ = (f"``scene_crowd(scene).{_f.__name__}(...)``: see "
                  f":meth:`CrowdHandle.{_f.__name__}`; ``scene`` defaults to the "
                  "context scene.")
del _f
