"""crowd_addon.api outside Blender: no bpy, scenes named explicitly or by the hook the
extension installs."""

import pytest

from crowd_addon import api
from crowd_addon.core import CrowdError


def test_no_scene_and_no_blender_context_is_a_clear_error():
    api.set_context_scene(None)
    with pytest.raises(CrowdError, match="no Blender context.*api.wrap"):
        api.on_event("step", lambda *a: None)


def test_the_context_hook_names_the_scene():
    api.set_context_scene(lambda: "Stadium")
    try:
        handle = api.on_event("step", lambda *a: None)
        assert api.scene_crowd("Stadium")._callbacks._handlers[handle][0] == "step"
        api.set_context_scene(lambda: None)
        with pytest.raises(CrowdError, match="context has none"):
            api.set_trigger("fans", "go")
    finally:
        api.set_context_scene(None)
        api.off(handle, scene="Stadium")
