"""Looks through Blender's own USD importer (issue 34, item 5): the look shot
(tests/usd/look_shot.py: looks through transitions, a unique, a move, a kid's
three-bone chain, looks started before, during and on the last frame of the shot and
looked away from) exported with ``layout="blender"`` and imported with
``bpy.ops.wm.usd_import``. At every shot frame each sampled agent's evaluated mesh
equals core's skinning with the looked rows (``Crowd.agent_rows``), and its head's
forward -- the rotation that carries the head sphere's bind vertices to where Blender
puts them -- is within 3 degrees of core's.
"""

import os
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from usd.conftest import FIRST, LAST  # noqa: E402
from usd.look_shot import AGENTS, LOOKERS, core_rows, look_config, simulate_looks  # noqa: E402

from crowd_addon.core.base.skinning import skin_vertices  # noqa: E402
from test_usd_import import import_agents, world_vertices  # noqa: E402

TOLERANCE = 1e-4          # metres


def rotation(p, q) -> np.ndarray:
    """The rotation that best carries points ``p`` onto ``q`` (Kabsch; any uniform scale
    between them left out)."""
    u, _, vt = np.linalg.svd((p - p.mean(0)).T @ (q - q.mean(0)))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    return vt.T @ np.diag([1, 1, d]) @ u.T


def angle(a, b):
    return np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    from crowd_addon.core import Crowd
    from crowd_addon.core.shots.recorder import record
    from crowd_addon.usd import export_crowd

    rec = record(Crowd(look_config(), skinning="gpu"), FIRST, LAST, before_step=simulate_looks)
    path = export_crowd(rec, tmp_path_factory.mktemp("looks") / "looks.usdc",
                        layout="blender", repetition=None).path
    return import_agents(path)


def test_blender_imports_the_looks_within_3_degrees_of_core(imported):
    truth, scales, skel = core_rows()
    cfg = look_config()
    names = list(cfg.skeletons)
    scene = bpy.context.scene
    worst_v, worst_a, turned = 0.0, 0.0, 0.0
    for frame in range(FIRST, LAST + 1):
        scene.frame_set(frame)
        rows, position, heading = truth[frame]
        for a in AGENTS:
            name = names[int(skel[a])]
            sk, mesh = cfg.skeletons[name], cfg.meshes[name][0]
            rig = cfg.look_rigs[name]
            c, s = np.cos(heading[a]), np.sin(heading[a])
            rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
            r = rows[a:a + 1, :sk.bone_count]
            v = skin_vertices(mesh.positions, mesh.bone_indices, mesh.bone_weights, r)[0]
            want = (v * scales[a]) @ rz.T + position[a]
            got = world_vertices(imported[a])
            worst_v = max(worst_v, float(np.abs(got - want).max()))
            assert np.abs(got - want).max() < TOLERANCE, (a, frame)
            # the head: vertices bound to it alone, their rotation from bind to Blender's
            head = sk.bone_index("head")
            w = mesh.bone_weights * (mesh.bone_indices == head)
            rigid = w.sum(1) > 0.999
            turn = rotation(mesh.positions[rigid], got[rigid])
            want_f = rz @ (r[0, head, :, :3] @ np.array(rig.forward))
            err = angle(turn @ np.array(rig.forward), want_f)
            worst_a = max(worst_a, err)
            assert err < 3.0, (a, frame, err)
            if a in LOOKERS:
                turned = max(turned, angle(rz @ (rows[a, head, :, :3] @ rig.forward),
                                           rz @ rig.forward))
    print(f"worst vertex error {worst_v:.2e} m, worst head angle {worst_a:.4f} degrees")
    assert turned > 20.0
