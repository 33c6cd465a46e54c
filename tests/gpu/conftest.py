"""Shared crowds and the headless GL context of the GPU tests.

The oracle everywhere is core: ``Crowd.agent_rows`` + ``skin_vertices`` (paper
Eq. 1) for skinned positions, ``PoseStorage`` for texture contents and dirty
bytes, a second ``Crowd`` blending on the CPU for the transition shader.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from crowd_addon.core import ClipPlayer, Crowd, CrowdConfig, skin_vertices
from crowd_addon.core.authoring import synthetic as sy
from crowd_addon.core.meshes.mesh import ProxyMesh

moderngl = pytest.importorskip("moderngl", reason="moderngl (crowd_addon[gpu]) not installed")


@pytest.fixture(scope="session")
def gl():
    """One headless OpenGL 4.3 context (EGL; Mesa llvmpipe needs no GPU)."""
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=430)
    except Exception as e:                                      # noqa: BLE001
        pytest.skip(f"no headless EGL OpenGL 4.3 context on this machine: {e}")
    yield ctx
    ctx.release()


spread_influences = sy.spread_weights


def make_config(M=8, streams=3, agents=24, NT=4, bones=24, max_texture_size=16384,
                spacing=1.5, lods=(0.25, 0.06, "card"), lod_distances=(30.0, 90.0, 150.0),
                uniques=1, influences=None):
    """A small crowd on a grid: ``streams`` streams, ``uniques`` uniques, agents at
    offsets ``0..M-1`` cycling, varied headings, colours and scales (0.8 .. 1.25), a
    proxy with LODs (the humanoid body, or with ``influences`` bones a vertex:
    :func:`spread_influences`)."""
    sk = sy.humanoid("fan", bones=bones)
    cfg = CrowdConfig(max_offset=M, transition_slots=NT, max_texture_size=max_texture_size,
                      lod_distances=lod_distances)
    cfg.add_skeleton(sk)
    for i in range(streams + uniques):
        cfg.add_clip(sy.periodic_clip(sk, f"c{i}", frames=13 + 6 * i, seed=3 + i))
    for s in range(streams):
        cfg.add_stream(f"s{s}", "fan", ClipPlayer(f"c{s}"))
    for u in range(uniques):
        cfg.add_unique(f"u{u}", "fan", ClipPlayer(f"c{streams + u}", speed=1.3))
    side = int(np.ceil(np.sqrt(agents)))
    grid = np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2)[:agents]
    cfg.add_agents(agents, streams=np.arange(agents) % streams,
                   offsets=(np.arange(agents) * 3) % M,
                   positions=np.c_[grid * spacing, np.zeros(agents)],
                   headings=np.linspace(0.0, 2 * np.pi, agents, endpoint=False),
                   scales=np.linspace(0.8, 1.25, agents)[::-1])
    if influences is None:
        mesh = sy.humanoid_mesh(sk)
    else:
        pos, tri, idx, w = spread_influences(sk, influences)
        mesh = ProxyMesh.from_influences("fan_body", "fan", pos, tri, idx, w,
                                         bone_count=sk.bone_count)
    cfg.add_mesh(mesh, lods=lods)
    return cfg


def make_unique(cfg, agents, unique=0):
    """Put ``agents`` on unique animation ``unique`` (config arrays, before Crowd())."""
    cfg.agent_stream[agents] = -1
    cfg.agent_unique[agents] = unique


def world_reference(crowd, agents, mesh, influences=None):
    """CPU reference (core.skin_vertices on crowd.agent_rows) of ``mesh`` for ``agents``,
    then each agent's scale, heading about +Z and position: (n, V, 3) float64.
    ``influences``:
    ``(indices, weights)`` to skin with instead of the mesh's own."""
    agents = np.asarray(agents)
    idx, w = influences or (mesh.bone_indices, mesh.bone_weights)
    local = skin_vertices(mesh.positions, idx, w, crowd.agent_rows(agents))
    local = local * crowd.agents.scale[agents].astype(np.float64)[:, None, None]
    h = crowd.agents.heading[agents].astype(np.float64)[:, None]
    c, s = np.cos(h), np.sin(h)
    x, y = local[..., 0], local[..., 1]
    world = np.stack([c * x - s * y, s * x + c * y, local[..., 2]], -1)
    return world + crowd.agents.position[agents].astype(np.float64)[:, None]


REFERENCE_VS = """#version 430 core
layout(location = 0) in vec3 in_world;
layout(location = 1) in vec3 in_normal;
layout(location = 2) in vec3 in_color;
uniform mat4 u_view_proj;
smooth out vec3 v_world;
smooth out vec3 v_shadow;
smooth out vec3 v_normal;
flat out vec3 v_color;
void main() {
  v_world = in_world; v_normal = in_normal; v_color = in_color;
  v_shadow = vec3(0.0);
  gl_Position = u_view_proj * vec4(in_world, 1.0);
}
"""


def _reference_colors(crowd, agents, mesh, skeleton):
    """(n, V, 3) the colour each vertex of ``mesh`` takes for ``agents``: the agent's
    tint where there are no looks, else the material's colour tinted where it is grey,
    and a palette material the agent's palette colour."""
    color = np.rint(np.clip(crowd.agents.color[agents], 0, 1) * 255) / 255
    color = np.broadcast_to(color[:, None], (agents.size, mesh.vertex_count, 3))
    if not mesh.looks:
        return color
    base = np.ones((mesh.vertex_count, 3))
    looks = np.array([look.color[:3] for look in mesh.looks])
    material = np.zeros(mesh.triangle_count, np.int64) if mesh.material is None \
        else mesh.material.astype(np.int64)
    base[mesh.triangles.reshape(-1)] = np.repeat(looks[material], 3, axis=0)
    base = np.rint(base * 255) / 255
    saturation = (base.max(1) - base.min(1)) / np.maximum(base.max(1), 1e-4)
    grey = np.clip(1 - 4 * saturation, 0, 1)[None, :, None]
    color = base[None] * (1 - grey) + base[None] * color * grey
    names = list(crowd.config.palette_materials.get(skeleton, ()))
    if names:                 # palette materials take each agent's palette colour instead
        column = np.full(mesh.vertex_count, -1)
        per_look = [names.index(k.name) if k.name in names else -1 for k in mesh.looks]
        column[mesh.triangles.reshape(-1)] = np.repeat(np.array(per_look)[material], 3)
        palette = crowd.agents.palette[agents]
        pal = np.rint(np.clip(palette, 0, 1) * 255) / 255                # (n, 4, 3)
        for c in range(4):
            on = (palette[:, c] >= 0).all(1)[:, None] & (column == c)[None]
            color = np.where(on[..., None], pal[:, c][:, None, :], color)
    return color


def reference_image(gl, crowd, camera, light, size):
    """Every agent's body (its LOD 0: mesh variant and props, ``crowd.view.bodies``)
    skinned on the CPU (core.skin_vertices), uploaded as one static mesh and drawn with
    the crowd's own fragment shader: ``(H, W, 4)`` uint8, top row first."""
    from crowd_addon.gpu.assembler import gl_sources
    from crowd_addon.gpu.programs import CROWD_DRAW
    view = crowd.view
    names = list(crowd.config.skeletons)
    verts, tris, base = [], [], 0
    for b, body in enumerate(view.bodies):
        mesh = body.levels[0]
        agents = np.flatnonzero(view.agent_body == b)
        world = world_reference(crowd, agents, mesh)
        rows = crowd.agent_rows(agents)
        normals = skin_vertices(mesh.normals, mesh.bone_indices, mesh.bone_weights, rows) - \
            skin_vertices(np.zeros_like(mesh.normals), mesh.bone_indices, mesh.bone_weights,
                          rows)
        hd = crowd.agents.heading[agents].astype(np.float64)[:, None]
        c, s = np.cos(hd), np.sin(hd)
        normals = np.stack([c * normals[..., 0] - s * normals[..., 1],
                            s * normals[..., 0] + c * normals[..., 1], normals[..., 2]], -1)
        color = _reference_colors(crowd, agents, mesh, names[body.skeleton])
        verts.append(np.concatenate([world, normals, color], -1).reshape(-1, 9))
        tris.append((mesh.triangles[None].astype(np.int64) + base
                     + (np.arange(agents.size) * mesh.vertex_count)[:, None, None]).reshape(-1, 3))
        base += agents.size * mesh.vertex_count
    verts = np.concatenate(verts).astype("f4")
    tris = np.concatenate(tris).astype("u4")
    prog = gl.program(vertex_shader=REFERENCE_VS,
                      fragment_shader=gl_sources(CROWD_DRAW, {"INFLUENCES": 4, "SHADOWS": 0,
                                                              "ENCODE_SRGB": 1})
                      ["fragment_shader"])
    prog["u_view_proj"].write(np.asarray(camera.view_projection, "f4").T.tobytes())
    prog["u_light"].value = light
    vbo, ibo = gl.buffer(verts.tobytes()), gl.buffer(tris.tobytes())
    vao = gl.vertex_array(prog, [(vbo, "3f 3f 3f", "in_world", "in_normal", "in_color")], ibo,
                          index_element_size=4)
    fbo = gl.framebuffer(color_attachments=[gl.renderbuffer(size, 4)],
                         depth_attachment=gl.depth_renderbuffer(size))
    fbo.use()
    fbo.clear(0.62, 0.66, 0.72, 1.0, depth=1.0)
    gl.enable(gl.DEPTH_TEST)
    vao.render()
    img = np.frombuffer(fbo.read(components=4, alignment=1), np.uint8)
    for obj in (vao, vbo, ibo, prog, fbo):
        obj.release()
    return img.reshape(size[1], size[0], 4)[::-1]


def assert_close_relative(actual, expected, rtol=1e-4):
    """``|actual - expected| <= rtol * max|expected|`` everywhere (relative to the scale
    of the values, as positions near 0 make per-element relative errors meaningless)."""
    scale = float(np.abs(expected).max())
    err = float(np.abs(np.asarray(actual, np.float64) - expected).max())
    assert err <= rtol * scale, f"max error {err:.3g} > {rtol} x {scale:.3g}"


@pytest.fixture
def h():
    """The helpers above (test modules are imported by path, not as a package)."""
    return SimpleNamespace(make_config=make_config, make_unique=make_unique,
                           spread_influences=spread_influences,
                           world_reference=world_reference, reference_image=reference_image,
                           assert_close_relative=assert_close_relative, Crowd=Crowd)


@pytest.fixture
def renderer(gl):
    """``renderer(crowd, size=(w, h), **kw)``: a ModernGLRenderer on the shared context,
    released after the test."""
    from crowd_addon.gpu.moderngl_backend import ModernGLRenderer
    made = []

    def build(crowd, size=(160, 120), **kw):
        made.append(ModernGLRenderer(crowd.view, gl, size, **kw))
        return made[-1]
    yield build
    for r in made:
        r.release()
