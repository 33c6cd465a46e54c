"""Shared crowds and the headless GL context of the GPU tests.

The oracle everywhere is core: ``Crowd.agent_rows`` + ``skin_vertices`` (paper
Eq. 1) for skinned positions, ``PoseStorage`` for texture contents and dirty
bytes, a second ``Crowd`` blending on the CPU for the transition shader.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from crowd_addon.core import ClipPlayer, Crowd, CrowdConfig, skin_vertices
from crowd_addon.core import synthetic as sy
from crowd_addon.core.mesh import ProxyMesh

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
                           world_reference=world_reference,
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
