"""The numpy F-curve evaluator (crowd_addon.core.bake.fcurve) against Blender's own
``FCurve.evaluate``: Blender is the oracle, so these tests need bpy."""

import numpy as np

from crowd_addon.blender.action_data import read_action
from crowd_addon.blender.armature import skeleton_from_armature
from crowd_addon.core.bake import fcurve

HANDLE_TYPES = ("FREE", "AUTO_CLAMPED", "AUTO", "VECTOR", "ALIGNED")


def pack(fcurves) -> fcurve.CurveSet:
    """Every key, interpolation and handle of ``fcurves`` packed as the bake packs them."""
    counts = [len(fc.keyframe_points) for fc in fcurves]
    start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    co, left, right = (np.zeros((start[-1], 2), np.float32) for _ in range(3))
    ipo = np.zeros(start[-1], np.int32)
    for fc, a, b in zip(fcurves, start[:-1], start[1:]):
        kp = fc.keyframe_points
        kp.foreach_get("co", co[a:b].reshape(-1))
        kp.foreach_get("interpolation", ipo[a:b])
        kp.foreach_get("handle_left", left[a:b].reshape(-1))
        kp.foreach_get("handle_right", right[a:b].reshape(-1))
    linear = np.array([fc.extrapolation == "LINEAR" for fc in fcurves])
    return fcurve.CurveSet(co, ipo, left, right, start, linear)


def random_curve(bag, rng, index):
    """1-8 keys at random frames, random interpolations and handle types, long free
    handles (overlap corrections), random extrapolation."""
    k = int(rng.integers(1, 9))
    frames = np.cumsum(rng.uniform(0.3, 6.0, k)) + rng.uniform(-10, 10)
    fc = bag.fcurves.new(f'pose.bones["b{index}"].location', index=0)
    fc.keyframe_points.add(k)
    fc.keyframe_points.foreach_set(
        "co", np.stack([frames, rng.normal(0, 2, k)], 1).astype(np.float32).ravel())
    for key in fc.keyframe_points:
        key.interpolation = rng.choice(["BEZIER", "BEZIER", "LINEAR", "CONSTANT"])
        key.handle_left_type = key.handle_right_type = rng.choice(HANDLE_TYPES)
    fc.extrapolation = rng.choice(["CONSTANT", "LINEAR"])
    fc.update()
    for key in fc.keyframe_points:
        if key.handle_left_type == "FREE":
            key.handle_left = (key.co[0] - rng.uniform(0, 8), key.co[1] + rng.normal(0, 3))
            key.handle_right = (key.co[0] + rng.uniform(0, 8), key.co[1] + rng.normal(0, 3))
    return fc


def test_random_curves_match_blender(scene, blend):
    rng = np.random.default_rng(7)
    _, _, bag = blend.new_action("curves")
    curves = [random_curve(bag, rng, i) for i in range(240)]
    packed = pack(curves)
    for c, fc in enumerate(curves):
        x = packed.co[packed.start[c]:packed.start[c + 1], 0]
        t = np.concatenate([rng.uniform(x[0] - 6, x[-1] + 6, 60), x, x + 0.5,
                            np.round(rng.uniform(x[0] - 2, x[-1] + 2, 10))]).astype(np.float32)
        got = fcurve.evaluate(packed, t, [c])[0]
        want = np.array([fc.evaluate(float(v)) for v in t], np.float32)
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6, err_msg=f"curve {c}")


def test_curves_keyed_alike_are_evaluated_together(scene, blend):
    """Grouped evaluation (shared time search and Bezier roots) equals one by one."""
    rng = np.random.default_rng(3)
    _, _, bag = blend.new_action("shared")
    frames = np.array([1.0, 4.0, 10.0, 13.0])
    fcs = [blend.add_curve(bag, 'pose.bones["b"].rotation_quaternion', i, frames,
                           rng.normal(size=4)) for i in range(4)]
    fcs.append(blend.add_curve(bag, 'pose.bones["c"].location', 0, frames + 0.5,
                               rng.normal(size=4)))
    packed = pack(fcs)
    assert sorted(len(g) for g in packed.groups(range(5))) == [1, 4]
    t = np.linspace(-2, 16, 97, dtype=np.float32)
    together = fcurve.evaluate(packed, t)
    alone = np.concatenate([fcurve.evaluate(packed, t, [c]) for c in range(5)])
    np.testing.assert_array_equal(together, alone)
    want = np.array([[fc.evaluate(float(v)) for v in t] for fc in fcs], np.float32)
    np.testing.assert_allclose(together, want, atol=2e-6)


def test_only_curves_it_reproduces_take_the_numpy_path(scene, blend):
    """Modifiers other than Cycles inside the key range, and easing between keys, are
    left to ``FCurve.evaluate``; sampled only on its keys, a curve is its key values
    whatever its interpolation, which is then not even read."""
    obj = blend.build_rig(scene)
    action, slot, bag = blend.new_action("Mixed")
    frames = np.arange(1.0, 11.0)
    plain = blend.add_curve(bag, 'pose.bones["leg"].location', 0, frames, np.sin(frames))
    eased = blend.add_curve(bag, 'pose.bones["leg"].location', 1, frames, frames, "SINE")
    noisy = blend.add_curve(bag, 'pose.bones["leg"].location', 2, frames, frames)
    noisy.modifiers.new("NOISE")
    cycled = blend.add_curve(bag, 'pose.bones["root"].location', 0, frames, frames)
    cycled.modifiers.new("CYCLES")
    sk = skeleton_from_armature(obj)
    src = read_action(obj, sk, action, fps=24, scene_fps=24, slot=slot)
    fast = {bc.fcurve: f for bc, f in zip(src.curves, src.fast)}
    assert fast == {plain: True, eased: True, noisy: False, cycled: True}
    assert (src.keys.ipo == fcurve.LINEAR).all()        # on keys: nothing more read
    action.use_frame_range = True
    action.frame_start, action.frame_end = 1, 15                     # Cycles now repeats
    src = read_action(obj, sk, action, fps=48, scene_fps=24, slot=slot)
    fast = {bc.fcurve: f for bc, f in zip(src.curves, src.fast)}
    assert fast == {plain: True, eased: False, noisy: False, cycled: False}
    assert (src.keys.ipo[:10] == fcurve.BEZIER).all()
