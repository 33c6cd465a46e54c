"""Mesh variants and props per agent (crowd_addon.core.meshes.bodies): the configuration's
checks, the bodies the agents use and their merged meshes, the seeded placement
draws, the validation, the file round trip and the repetition metric.

The oracles are written here from the definitions: a body is the variant's levels
with each prop's vertices appended (bit order) to every level; bodies
are ordered by (skeleton, variant, props) (the sorted set of the agents' triples);
a prop weighted 1 to one bone moves by that bone's skinning matrix (CPU skinning of
the parts one by one, and of the bind positions by the bone's row alone); shares
are checked on thousands of draws; the repetition metric against the brute-force
pair count of tests/core/test_repetition.py with each agent's body as its look."""

import numpy as np
import pytest

from crowd_addon.core import ClipPlayer, Crowd, CrowdConfig, CrowdError, skin_vertices
from crowd_addon.core.authoring import synthetic as sy
from crowd_addon.core.meshes.bodies import (MAX_PROPS, Prop, body_keys, crowd_bodies, is_card,
                                            merge_meshes, rigid_mesh)
from crowd_addon.core.authoring.config import validate_config
from crowd_addon.core.authoring.config_io import config_digest, load_config, save_config
from crowd_addon.core.meshes.mesh import ProxyMesh
from crowd_addon.core.authoring.placement import CharacterStreams, PlacementPolicy, place_agents
from crowd_addon.core.shots.recorder import record
from crowd_addon.core.variety.repetition import (RepetitionSettings, crowd_repetition,
                                                 recording_repetition)

from .test_repetition import brute_metric, top_view

FAN_BONES, KID_BONES = 24, 26


def base_config(agents=0):
    """Two characters with bodies ("fan": variant 0 ``fan_body`` with LODs and a card,
    variant 1 ``slim``; "kid": one body without LODs), no props yet, one stream each."""
    fan, kid = sy.humanoid("fan", FAN_BONES), sy.humanoid("kid", KID_BONES)
    cfg = CrowdConfig(max_offset=6, transition_slots=2, seed=3)
    for sk, clip in ((fan, "walk"), (kid, "run")):
        cfg.add_skeleton(sk)
        cfg.add_clip(sy.periodic_clip(sk, clip, frames=11, seed=len(clip)))
        cfg.add_stream(clip, sk.name, ClipPlayer(clip))
    cfg.add_mesh(sy.humanoid_mesh(fan))                      # fan_body, lod1, lod2, card
    cfg.add_variant(sy.humanoid_mesh(fan, sides=5, name="slim"))
    cfg.add_mesh(sy.humanoid_mesh(kid), lods=())
    return cfg


def flag(skeleton):
    """A long pole in the left hand (it swings far with the arm)."""
    return sy.box_prop(skeleton, "hand.L", "flag", size=(0.03, 0.03, 0.7), offset=(0, 0, 0.25))


def cap(skeleton):
    return sy.box_prop(skeleton, "head", "cap", size=(0.22, 0.22, 0.06), offset=(0, 0, 0.21))


def props_config():
    """:func:`base_config` with props flag (bit 0) and cap (bit 1) on the fan and a
    ball (bit 0) on the kid."""
    cfg = base_config()
    fan, kid = cfg.skeletons["fan"], cfg.skeletons["kid"]
    assert cfg.add_prop(flag(fan)) == 0
    assert cfg.add_prop(cap(fan)) == 1
    assert cfg.add_prop(sy.box_prop(kid, "hand.L", "ball", size=(0.2, 0.2, 0.2))) == 0
    return cfg


#: a hand-made crowd: (stream 0 = fan / 1 = kid, variant, props) per agent
HAND_MADE = [(1, 0, 0), (0, 1, 2), (0, 0, 0), (1, 0, 1), (0, 1, 2), (0, 0, 3), (0, 1, 0),
             (0, 0, 1), (1, 0, 1), (0, 0, 3)]


def hand_made_config():
    cfg = props_config()
    st, var, pro = (np.array(c) for c in zip(*HAND_MADE))
    n = len(HAND_MADE)
    cfg.add_agents(n, streams=st, offsets=np.arange(n) % 6, variants=var, props=pro,
                   positions=np.c_[np.arange(n) * 1.5, np.zeros((n, 2))])
    return cfg


# --------------------------------------------------------------------- config errors
def test_add_variant_needs_a_body_and_a_new_name():
    cfg = CrowdConfig()
    sk = cfg.add_skeleton(sy.humanoid("fan", FAN_BONES))
    with pytest.raises(CrowdError, match=r"mesh variant 'slim': skeleton 'fan' has no body "
                                         r"yet \(add_mesh first"):
        cfg.add_variant(sy.humanoid_mesh(sk, name="slim"))
    assert cfg.mesh_variants("fan") == []
    cfg.add_mesh(sy.humanoid_mesh(sk), lods=())
    assert cfg.add_variant(sy.humanoid_mesh(sk, sides=5, name="slim"), lods=()) == 1
    assert cfg.add_variant(sy.humanoid_mesh(sk, sides=6, name="broad"), lods=(0.5,)) == 2
    with pytest.raises(CrowdError, match=r"mesh variant 'slim': skeleton 'fan' has a variant "
                                         r"of that name already"):
        cfg.add_variant(sy.humanoid_mesh(sk, sides=7, name="slim"))
    with pytest.raises(CrowdError, match="mesh variant 'fan_body'.*of that name already"):
        cfg.add_variant(sy.humanoid_mesh(sk, sides=7))           # variant 0's name
    assert [[m.name for m in levels] for levels in cfg.mesh_variants("fan")] == \
        [["fan_body"], ["slim"], ["broad", "broad.lod1"]]


def test_add_prop_checks_skeleton_name_bones_and_count():
    cfg = base_config()
    fan = cfg.skeletons["fan"]
    ghost = rigid_mesh("hat", "ghost", 0, np.eye(3), [[0, 1, 2]])
    with pytest.raises(CrowdError, match=r"prop 'hat': unknown skeleton 'ghost' \(known: "
                                         r"\['fan', 'kid'\]\)"):
        cfg.add_prop(Prop("hat", "ghost", 0, ghost))
    far = rigid_mesh("far", "fan", 30, np.eye(3), [[0, 1, 2]])       # unchecked bone count
    with pytest.raises(CrowdError, match=r"prop 'far': mesh 'far': uses bone 30 but skeleton "
                                         r"'fan' has 24 bones"):
        cfg.add_prop(Prop("far", "fan", 30, far))
    assert cfg.add_prop(flag(fan)) == 0
    with pytest.raises(CrowdError, match="prop 'flag': skeleton 'fan' has a prop of that "
                                         "name already"):
        cfg.add_prop(sy.box_prop(fan, "head", "flag"))
    for j in range(1, MAX_PROPS):
        assert cfg.add_prop(sy.box_prop(fan, "head", f"p{j}")) == j
    with pytest.raises(CrowdError, match="prop 'p8': skeleton 'fan' has 8 props already"):
        cfg.add_prop(sy.box_prop(fan, "head", "p8"))
    assert len(cfg.props["fan"]) == MAX_PROPS and "kid" not in cfg.props
    # the kid's props are counted on their own
    assert cfg.add_prop(sy.box_prop(cfg.skeletons["kid"], "head", "flag")) == 0


def test_prop_must_be_a_rigid_mesh_of_its_skeleton():
    tri, pos = [[0, 1, 2]], np.eye(3)
    good = rigid_mesh("m", "fan", 4, pos, tri, FAN_BONES)
    assert Prop("p", "fan", 4, good).bone == 4
    assert Prop("p", "fan", np.int64(4), good).bone == 4
    with pytest.raises(CrowdError, match="a prop of skeleton 'fan' has an empty name"):
        Prop("  ", "fan", 4, good)
    with pytest.raises(CrowdError, match="prop 'p': mesh must be a ProxyMesh, got ndarray"):
        Prop("p", "fan", 4, pos)
    with pytest.raises(CrowdError, match="prop 'p': its mesh is for skeleton 'fan', not 'kid'"):
        Prop("p", "kid", 4, good)
    with pytest.raises(CrowdError, match="prop 'p': every vertex must be weighted 1 to bone 5"):
        Prop("p", "fan", 5, good)                                  # the mesh follows bone 4
    two = ProxyMesh.from_influences("two", "fan", pos, tri, [[4, 5]] * 3, [[0.6, 0.4]] * 3,
                                    bone_count=FAN_BONES)
    with pytest.raises(CrowdError, match="prop 'p': every vertex must be weighted 1 to bone 4"):
        Prop("p", "fan", 4, two)
    mixed = ProxyMesh.from_influences("mixed", "fan", pos, tri, [[4], [4], [6]], np.ones((3, 1)),
                                      bone_count=FAN_BONES)
    with pytest.raises(CrowdError, match="every vertex must be weighted 1 to bone 4"):
        Prop("p", "fan", 4, mixed)


def test_rigid_mesh_weights_every_vertex_to_one_bone_and_validates():
    pos = np.random.default_rng(0).normal(size=(5, 3))
    m = rigid_mesh("m", "fan", 7, pos, [[0, 1, 2], [2, 3, 4]], FAN_BONES)
    np.testing.assert_array_equal(m.bone_indices[:, 0], 7)
    np.testing.assert_array_equal(m.bone_weights[:, 0], 1.0)
    assert not m.bone_weights[:, 1:].any()
    np.testing.assert_allclose(m.positions, pos, atol=1e-6)
    with pytest.raises(CrowdError, match=r"mesh 'm': vertex 0 uses bone index \[24, 0, 0, 0\], "
                                         r"outside 0\.\.23"):
        rigid_mesh("m", "fan", FAN_BONES, pos, [[0, 1, 2]], FAN_BONES)
    with pytest.raises(CrowdError, match=r"mesh 'm': triangle 1 \[2, 3, 5\] refers to a vertex "
                                         r"outside 0\.\.4"):
        rigid_mesh("m", "fan", 1, pos, [[0, 1, 2], [2, 3, 5]], FAN_BONES)


def test_add_agents_rejects_variants_and_props_out_of_their_type():
    cfg = base_config()
    with pytest.raises(CrowdError, match=r"agents: variant must be integers in 0\.\.32767, got "
                                         r"int64 -1\.\.0"):
        cfg.add_agents(2, streams=0, variants=[0, -1])
    with pytest.raises(CrowdError, match=r"agents: props must be integers in 0\.\.255"):
        cfg.add_agents(2, streams=0, props=[256, 0])
    with pytest.raises(CrowdError, match="agents: props must be integers"):
        cfg.add_agents(2, streams=0, props=[0.5, 1.0])
    assert cfg.agent_count == 0
    cfg.add_agents(3, streams=0)                       # none given: zeros, arrays left empty
    assert cfg.agent_variant.size == 0 and cfg.agent_props.size == 0
    np.testing.assert_array_equal(cfg.variant_ids, [0, 0, 0])
    cfg.add_agents(2, streams=0, variants=[1, 1])     # earlier agents filled with 0
    cfg.add_agents(1, streams=1)                       # later ones too
    np.testing.assert_array_equal(cfg.agent_variant, [0, 0, 0, 1, 1, 0])
    assert cfg.agent_variant.dtype == np.int16
    np.testing.assert_array_equal(cfg.prop_masks, np.zeros(6))
    assert cfg.prop_masks.dtype == np.uint8


# ------------------------------------------------------------------------ the bodies
def test_bodies_are_ordered_by_skeleton_variant_props():
    cfg = hand_made_config()
    skel = np.array([s for s, _, _ in HAND_MADE])          # stream 0 is the fan's, 1 the kid's
    bodies, agent_body = crowd_bodies(cfg, skel)
    want = sorted(set(HAND_MADE))                            # skeleton index == stream here
    assert [(b.skeleton, b.variant, b.props) for b in bodies] == want
    np.testing.assert_array_equal(agent_body, [want.index(t) for t in HAND_MADE])
    assert agent_body.dtype == np.int64
    assert [b.name for b in bodies] == ["fan_body", "fan_body+flag", "fan_body+flag+cap",
                                        "slim", "slim+cap", "kid_body", "kid_body+ball"]
    assert [b.prop_ids for b in bodies] == [[], [0], [0, 1], [], [1], [], [0]]
    keys, index = body_keys(cfg, skel)
    np.testing.assert_array_equal(keys, want)
    np.testing.assert_array_equal(index, agent_body)
    # the crowd's view: the same, the skeleton of each agent found from its stream
    crowd = Crowd(cfg)
    assert [b.name for b in crowd.view.bodies] == [b.name for b in bodies]
    np.testing.assert_array_equal(crowd.view.agent_body, agent_body)
    with pytest.raises(CrowdError, match=r"crowd: 9 agents but agent_variant / agent_props "
                                         r"hold \(10,\) / \(10,\)"):
        body_keys(cfg, skel[:9])


def test_a_body_merges_its_props_into_every_level():
    cfg = hand_made_config()
    bodies, _ = crowd_bodies(cfg, [s for s, _, _ in HAND_MADE])
    by_name = {b.name: b for b in bodies}
    fan_props = cfg.props["fan"]
    for body in bodies:
        skeleton = list(cfg.skeletons)[body.skeleton]
        variant = cfg.mesh_variants(skeleton)[body.variant]
        parts = [cfg.props[skeleton][j].mesh for j in body.prop_ids]
        assert len(body.levels) == len(variant)
        for level, mesh in zip(body.levels, variant):
            assert is_card(level) == is_card(mesh)    # the far levels keep their kind
            if not parts:
                assert level is mesh
                continue
            expect = [mesh, *parts]
            v = np.cumsum([0] + [p.vertex_count for p in expect])
            assert level.vertex_count == v[-1]
            assert level.triangle_count == sum(p.triangle_count for p in expect)
            t = 0
            for p, start in zip(expect, v):
                np.testing.assert_array_equal(level.positions[start:start + p.vertex_count],
                                              p.positions)
                np.testing.assert_array_equal(
                    level.triangles[t:t + p.triangle_count].astype(np.int64),
                    p.triangles.astype(np.int64) + start)
                w = p.influences
                np.testing.assert_array_equal(
                    level.bone_indices[start:start + p.vertex_count, :w], p.bone_indices)
                np.testing.assert_array_equal(
                    level.bone_weights[start:start + p.vertex_count, :w], p.bone_weights)
                assert not level.bone_weights[start:start + p.vertex_count, w:].any()
                t += p.triangle_count
    # the far levels carry the props too (a raised flag is what shows above far fans)
    assert [m.name for m in by_name["slim+cap"].levels] == [
        "slim+cap", "slim.lod1+cap", "slim.lod2+cap", "slim+cap.card", "slim.joined+cap.card"]
    assert by_name["fan_body+flag"].levels[0].vertex_count == \
        cfg.meshes["fan"][0].vertex_count + fan_props[0].mesh.vertex_count


def test_merge_meshes_of_one_part_is_that_part_and_keeps_looks_by_name():
    from crowd_addon.core.meshes.mesh import Look
    cfg = props_config()
    body, prop = cfg.meshes["kid"][0], cfg.props["kid"][0].mesh
    assert merge_meshes("x", [body]) is body
    red = Look("red", (1.0, 0.0, 0.0, 1.0))
    looked = rigid_mesh("ball", "kid", 10, prop.positions, prop.triangles, KID_BONES,
                        looks=(red,))
    merged = merge_meshes("kid+ball", [body, looked])
    # the body has no look: it takes a grey one named after it, the prop keeps its own
    assert [k.name for k in merged.looks] == ["kid_body", "red"]
    np.testing.assert_array_equal(merged.material[:body.triangle_count], 0)
    np.testing.assert_array_equal(merged.material[body.triangle_count:], 1)
    assert merged.uvs is None


def crowd_at(cfg, frames=4):
    crowd = Crowd(cfg)
    for _ in range(frames):
        crowd.step()
    return crowd


def test_merged_skinning_is_the_parts_skinned_apart_and_props_move_rigidly():
    """Core skinning of a body's merged level equals the variant's level and each prop
    skinned on their own with the same rows; a prop's skinned vertices are its bone's
    skinning matrix times its bind positions, at the bind pose's distances."""
    cfg = hand_made_config()
    crowd = crowd_at(cfg, 5)
    view = crowd.view
    checked = 0
    for b, body in enumerate(view.bodies):
        agents = np.flatnonzero(view.agent_body == b)
        rows = view.agent_rows(agents)
        skeleton = list(cfg.skeletons)[body.skeleton]
        variant = cfg.mesh_variants(skeleton)[body.variant]
        props = [cfg.props[skeleton][j] for j in body.prop_ids]
        for level, mesh in zip(body.levels, variant):
            merged = skin_vertices(level.positions, level.bone_indices, level.bone_weights, rows)
            apart = np.concatenate(
                [skin_vertices(m.positions, m.bone_indices, m.bone_weights, rows)
                     for m in [mesh] + [p.mesh for p in props]], 1)
            np.testing.assert_allclose(merged, apart, rtol=0, atol=1e-9)
        for p in props:
            moved = skin_vertices(p.mesh.positions, p.mesh.bone_indices, p.mesh.bone_weights,
                                  rows)                                      # (n, V, 3)
            m = rows[:, p.bone].astype(np.float64)                          # (n, 3, 4)
            rigid = np.einsum("nrc,vc->nvr", m[..., :3], p.mesh.positions) + m[:, None, :, 3]
            np.testing.assert_allclose(moved, rigid, rtol=0, atol=1e-6)
            bind = p.mesh.positions.astype(np.float64)
            d0 = np.linalg.norm(bind[:, None] - bind[None], axis=-1)
            d = np.linalg.norm(moved[:, :, None] - moved[:, None], axis=-1)
            np.testing.assert_allclose(d, np.broadcast_to(d0, d.shape), atol=1e-5)
            assert np.abs(moved - bind).max() > 0.05                 # it did move
            checked += 1
    assert checked == 5           # flag, flag + cap, cap (slim), ball


# ------------------------------------------------------------------------- placement
def grid(nx, ny):
    x, y = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float))
    return np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1), np.zeros(x.size)


CAST = (CharacterStreams("fan", ("walk",), variant_weights=(1.0, 3.0), prop_shares=(0.3, 0.8)),
        CharacterStreams("kid", ("run",), prop_shares=(0.5,)))


def place(cast=CAST, points=None, seed=4, policy=PlacementPolicy(), attribute=None):
    pos, heading = grid(80, 50) if points is None else points
    return place_agents("agent source 'stands'", pos, heading, policy, characters=cast,
                        max_offset=6, seed=seed, attribute=attribute)


def test_placement_draws_variants_and_props_seeded():
    a, b, c = place(seed=4), place(seed=4), place(seed=5)
    assert a.variants.dtype == np.int16 and a.props.dtype == np.uint8
    np.testing.assert_array_equal(a.variants, b.variants)
    np.testing.assert_array_equal(a.props, b.props)
    assert (a.variants != c.variants).any() and (a.props != c.props).any()
    assert (a.variants != c.variants).mean() > 0.2


def test_placement_shares_and_weights_are_respected():
    a = place()
    fan, kid = a.characters == 0, a.characters == 1
    assert 1500 < fan.sum() < 2500 and a.count == 4000
    assert set(np.unique(a.variants[fan]).tolist()) == {0, 1}
    assert 0.72 < (a.variants[fan] == 1).mean() < 0.78                 # weights 1 : 3
    assert (a.variants[kid] == 0).all()                                # one body
    flag, cap = (a.props[fan] & 1) > 0, (a.props[fan] & 2) > 0
    assert 0.25 < flag.mean() < 0.35 and 0.75 < cap.mean() < 0.85
    assert 0.2 < (flag & cap).mean() < 0.28                            # drawn on their own
    assert (a.props[fan] < 4).all() and (a.props[kid] < 2).all()       # only their own bits
    assert 0.45 < (a.props[kid] == 1).mean() < 0.55
    # a zero weight never draws its variant; shares 0 and 1 are none and all
    none = place((CharacterStreams("fan", ("walk",), variant_weights=(0.0, 1.0, 1.0),
                                   prop_shares=(0.0, 1.0)),))
    assert set(np.unique(none.variants).tolist()) == {1, 2}
    assert (none.props == 2).all()


def test_placement_rejects_bad_weights_shares_and_prop_counts():
    def cast(**kw):
        return (CharacterStreams("fan", ("walk",), **kw),)
    with pytest.raises(CrowdError, match=r"agent source 'stands': character 'fan': mesh "
                                         r"variant weights must be non-negative"):
        place(cast(variant_weights=(1.0, -1.0)))
    with pytest.raises(CrowdError, match="mesh variant weights must be non-negative with a "
                                         "positive sum"):
        place(cast(variant_weights=(0.0, 0.0)))
    with pytest.raises(CrowdError, match=r"character 'fan': prop 1's share must be in 0\.\.1, "
                                         r"got 1\.5"):
        place(cast(prop_shares=(0.5, 1.5)))
    with pytest.raises(CrowdError, match="character 'fan': 9 props; at most 8"):
        place(cast(prop_shares=(0.5,) * 9))


def test_placement_reads_variants_from_an_attribute():
    pos, heading = grid(6, 5)
    n = len(pos)
    look = np.arange(n) % 3

    def attribute(name, kind):
        assert kind == "int"
        if name != "look":
            raise CrowdError(f"no attribute {name!r}")
        return look

    cast = (CharacterStreams("fan", ("walk",), variant_weights=(1, 1, 1),
                             variant_mode="ATTRIBUTE", variant_attribute="look"),)
    a = place(cast, (pos, heading), attribute=attribute)
    np.testing.assert_array_equal(a.variants, look)
    assert (place(cast, (pos, heading), seed=99, attribute=attribute).variants == look).all()
    look[7] = 3
    with pytest.raises(CrowdError, match=r"agent source 'stands': character 'fan': attribute "
                                         r"'look' gives mesh variant 3 at point 7; it has "
                                         r"variants 0\.\.2"):
        place(cast, (pos, heading), attribute=attribute)
    look[7], look[12] = 0, -1
    with pytest.raises(CrowdError, match="gives mesh variant -1 at point 12"):
        place(cast, (pos, heading), attribute=attribute)
    with pytest.raises(CrowdError, match="this source has no point attributes "
                                         r"\(wanted 'look'\)"):
        place(cast, (pos, heading))


def test_placement_attribute_points_are_crowd_wide_with_two_characters():
    """Only the fan reads the attribute; the point named is the source's point, not
    its rank among the fan's agents."""
    pos, heading = grid(4, 4)
    n = len(pos)
    char = np.arange(n) % 2                    # even points: fans, odd: kids
    value = np.zeros(n, np.int64)
    value[1::2] = 9                            # out of range, but on kids: not read
    value[6] = 2

    def attribute(name, kind):
        return char if name == "character" else value

    cast = (CharacterStreams("fan", ("walk",), variant_weights=(1, 1),
                             variant_mode="ATTRIBUTE"), CharacterStreams("kid", ("run",)))
    with pytest.raises(CrowdError, match="attribute 'variant' gives mesh variant 2 at point 6"):
        place(cast, (pos, heading), policy=PlacementPolicy(character_mode="ATTRIBUTE"),
              attribute=attribute)
    value[6] = 1
    a = place(cast, (pos, heading), policy=PlacementPolicy(character_mode="ATTRIBUTE"),
              attribute=attribute)
    np.testing.assert_array_equal(a.variants, np.where(char == 0, value, 0))


def test_placed_agents_carry_their_bodies_into_the_crowd():
    cfg = props_config()
    pos, heading = grid(8, 5)
    a = place(points=(pos, heading), seed=8)
    a.add_to(cfg)
    np.testing.assert_array_equal(cfg.variant_ids, a.variants)
    np.testing.assert_array_equal(cfg.prop_masks, a.props)
    crowd = Crowd(cfg)
    np.testing.assert_array_equal(crowd.view.agent_skeleton, a.characters)
    bodies = crowd.view.bodies
    got = [(bodies[b].skeleton, bodies[b].variant, bodies[b].props)
           for b in crowd.view.agent_body]
    assert got == list(zip(a.characters.tolist(), a.variants.tolist(), a.props.tolist()))


# ------------------------------------------------------------------------ validation
def test_validate_config_names_the_agent_with_a_variant_or_prop_it_lacks():
    cfg = hand_made_config()
    validate_config(cfg)
    bad = cfg.agent_variant.copy()
    bad[4] = 2                                                         # the fan has 0..1
    cfg.agent_variant = bad
    with pytest.raises(CrowdError, match=r"agent 4: mesh variant 2, but character 'fan' has "
                                         r"variants 0\.\.1"):
        validate_config(cfg)
    with pytest.raises(CrowdError, match="agent 4: mesh variant 2"):
        Crowd(cfg)
    bad[4], bad[0] = 1, 1                                              # agent 0 is a kid
    with pytest.raises(CrowdError, match=r"agent 0: mesh variant 1, but character 'kid' has "
                                         r"variants 0\.\.0"):
        validate_config(cfg)
    bad[0] = 0
    props = cfg.agent_props.copy()
    props[6] = 4                                                       # the fan has 2 props
    cfg.agent_props = props
    with pytest.raises(CrowdError, match="agent 6: carries props 0b100, but character 'fan' "
                                         "has 2 props"):
        validate_config(cfg)
    props[6], props[3] = 0, 2                                          # the kid has 1 prop
    with pytest.raises(CrowdError, match="agent 3: carries props 0b10, but character 'kid' "
                                         "has 1 props"):
        Crowd(cfg)
    props[3] = 1
    validate_config(cfg)
    cfg.agent_props = props[:5]
    with pytest.raises(CrowdError, match=r"crowd: agent_props must be \(10,\) or empty, got "
                                         r"\(5,\)"):
        validate_config(cfg)


def test_validate_config_rejects_variants_without_a_body():
    cfg = base_config()
    cfg.add_agents(2, streams=0)
    cfg.variants["kid"] = [cfg.variants["fan"][0]]
    del cfg.meshes["kid"]
    with pytest.raises(CrowdError, match="crowd: skeleton 'kid' has mesh variants but no body"):
        validate_config(cfg)


# ----------------------------------------------------------------------- round trip
def assert_same_mesh(a, b):
    assert a.name == b.name and a.skeleton == b.skeleton
    for k in ("positions", "triangles", "bone_indices", "bone_weights", "normals"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k), err_msg=k)
    assert [k.name for k in a.looks] == [k.name for k in b.looks]


def test_save_and_load_keep_variants_props_and_each_agents_body(tmp_path):
    cfg = hand_made_config()
    path = tmp_path / "crowd.json"
    save_config(cfg, path)
    loaded = load_config(path)
    for skel in cfg.skeletons:
        want, got = cfg.mesh_variants(skel), loaded.mesh_variants(skel)
        assert len(got) == len(want)
        for lw, lg in zip(want, got):
            assert len(lw) == len(lg)
            for a, b in zip(lw, lg):
                assert_same_mesh(a, b)
        assert [(p.name, p.skeleton, p.bone) for p in loaded.props.get(skel, [])] == \
            [(p.name, p.skeleton, p.bone) for p in cfg.props.get(skel, [])]
        for p, q in zip(cfg.props.get(skel, []), loaded.props.get(skel, [])):
            assert_same_mesh(p.mesh, q.mesh)
    np.testing.assert_array_equal(loaded.variant_ids, cfg.variant_ids)
    np.testing.assert_array_equal(loaded.prop_masks, cfg.prop_masks)
    assert loaded.variant_ids.dtype == np.int16 and loaded.prop_masks.dtype == np.uint8
    assert config_digest(loaded) == config_digest(cfg)
    a, b = Crowd(cfg), Crowd(loaded)
    np.testing.assert_array_equal(b.view.agent_body, a.view.agent_body)
    assert [x.name for x in b.view.bodies] == [x.name for x in a.view.bodies]
    for x, y in zip(a.view.bodies, b.view.bodies):
        assert (x.skeleton, x.variant, x.props) == (y.skeleton, y.variant, y.props)
        for m, n in zip(x.levels, y.levels):
            assert_same_mesh(m, n)


def test_a_crowd_without_variants_or_props_saves_none(tmp_path):
    import json
    cfg = base_config()
    cfg.add_agents(4, streams=0)
    save_config(cfg, tmp_path / "plain.json")
    m = json.loads((tmp_path / "plain.json").read_text())
    assert "variant" not in m["agents"] and "props" not in m["agents"]
    assert "props" not in m
    loaded = load_config(tmp_path / "plain.json")
    assert loaded.agent_variant.size == 0 and loaded.agent_props.size == 0
    assert len(loaded.mesh_variants("fan")) == 2       # the variant itself is kept


# ------------------------------------------------------------------------ repetition
def test_repetition_counts_agents_of_different_bodies_as_not_alike():
    """One stream, one offset, one colour: every neighbour pair looks alike (1.0) while
    all agents share a body; with a prop on half of them the metric is the brute-force
    share of pairs of the same body."""
    s = RepetitionSettings(k=4, width=640, height=480)
    vp = top_view(20.0)

    def config(props):
        cfg = props_config()
        n = 36
        side = np.arange(n)
        pos = np.c_[(side % 6) * 3.0 - 8, (side // 6) * 3.0 - 8, np.zeros(n)]
        cfg.add_agents(n, streams=0, offsets=np.zeros(n, np.int64), positions=pos,
                       colors=np.full((n, 3), 0.5), props=props)
        return cfg

    def crowd(props):
        c = Crowd(config(props))
        c.step()
        return c

    same = crowd(None)
    assert len(same.view.bodies) == 1
    assert crowd_repetition(same.view, vp, settings=s).value == 1.0
    carry = np.random.default_rng(2).permutation(np.repeat([0, 1], 18)).astype(np.uint8)
    mixed = crowd(carry)
    view = mixed.view
    assert [b.name for b in view.bodies] == ["fan_body", "fan_body+flag"]
    np.testing.assert_array_equal(view.agent_body, carry)
    a = view.agents
    got = crowd_repetition(view, vp, settings=s).value
    want = brute_metric(a.position, a.kind, a.ref, a.offset, view.agent_body, a.color, vp, s)
    assert got == pytest.approx(want, abs=1e-12)
    assert 0.2 < got < 0.8
    # a recording of the same crowd measures the same at that frame
    rec = record(Crowd(config(carry), skinning="gpu"), view.frame, view.frame + 1)
    assert recording_repetition(rec, vp, frames=[view.frame], settings=s).per_frame == (got,)
    # the skeleton alone would call every pair alike
    assert brute_metric(a.position, a.kind, a.ref, a.offset, view.agent_skeleton, a.color,
                        vp, s) == 1.0
