"""moderngl and Blender's ``gpu`` module drawing in one GL context.

The viewport preview draws the crowd with moderngl inside Blender's OpenGL context
(:meth:`crowd_addon.gpu.moderngl_backend.ModernGLRenderer.attach`). Both libraries
cache GL state; :class:`SharedContext` brackets each moderngl draw so that neither
cache is left wrong (tests/blender/test_extension_preview.py draws with Blender right
before and after the crowd and checks both images).
"""

from __future__ import annotations

__all__ = ["SharedContext", "shared_context"]


class SharedContext:
    """moderngl drawing inside Blender's GL context, with both sides' state kept right.

    Blender's GL backend caches what it last bound (program, texture and sampler per
    unit, depth state) and skips binds it believes redundant, so after moderngl draws
    its cache is stale and Blender's next draws (overlays, text) go astray. Before a
    draw, :meth:`before` unbinds Blender's sampler objects from the crowd program's
    texture units (a mipmapping sampler would make our textures incomplete) and sets
    a depth function; after it, :meth:`after` draws one degenerate triangle through
    Blender's ``gpu`` module with a shader sampling those units, the depth test set to
    ALWAYS, so Blender binds its own program, textures, samplers and depth state
    again, then restores the caller's depth state through ``gpu.state`` (applied by
    Blender's next draw). Two shader/texture pairs alternate so the sync draw is never
    a bind Blender would skip.
    """

    def __init__(self, units):
        import gpu
        from gpu_extras.batch import batch_for_shader
        self.units = units
        self.pairs = []
        for _ in range(2):
            info = gpu.types.GPUShaderCreateInfo()
            info.vertex_in(0, "VEC3", "pos")
            for u in range(units):
                info.sampler(u, "FLOAT_2D", f"tex{u}")
            info.fragment_out(0, "VEC4", "color")
            info.vertex_source("void main() { gl_Position = vec4(pos, 1.0); }")
            info.fragment_source("void main() { color = " + " + ".join(
                f"texelFetch(tex{u}, ivec2(0), 0)" for u in range(units)) + "; }")
            shader = gpu.shader.create_from_info(info)
            batch = batch_for_shader(shader, "TRIS", {"pos": [(2.0, 2.0, 0.0)] * 3})
            self.pairs.append((shader, batch, gpu.types.GPUTexture((1, 1), format="RGBA8")))
        self.turn = 0

    def before(self, ctx):
        ctx.clear_samplers(0, self.units)
        ctx.depth_func = "<="

    def after(self):
        import gpu
        shader, batch, dummy = self.pairs[self.turn]
        self.turn ^= 1
        depth, mask = gpu.state.depth_test_get(), gpu.state.depth_mask_get()
        gpu.state.depth_test_set("ALWAYS")
        gpu.state.depth_mask_set(True)
        gpu.state.color_mask_set(True, True, True, True)
        shader.bind()
        for u in range(self.units):
            shader.uniform_sampler(f"tex{u}", dummy)
        batch.draw(shader)
        gpu.state.depth_test_set(depth)
        gpu.state.depth_mask_set(mask)


_SHARED: dict = {}


def shared_context() -> SharedContext:
    """The :class:`SharedContext` for the crowd program's texture units (made once,
    in the GPU context current now)."""
    from ..gpu.programs import CROWD_DRAW
    units = 1 + max(slot for slot, _, _ in CROWD_DRAW.samplers)
    if units not in _SHARED:
        _SHARED[units] = SharedContext(units)
    return _SHARED[units]
