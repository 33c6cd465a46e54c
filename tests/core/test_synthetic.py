"""The synthetic paper configuration the benchmarks share."""

from crowd_addon.core import Blend2, BlendSpace2D, ClipPlayer, Crowd, Layer, StateMachine
from crowd_addon.core.authoring import synthetic


def test_paper_config_has_the_papers_sizes_and_every_tree_kind():
    cfg = synthetic.paper_config(50, streams=10, max_offset=12, slots=20, bones=30)
    assert (len(cfg.streams), cfg.max_offset, cfg.transition_slots) == (10, 12, 20)
    assert cfg.skeletons["fan"].bone_count == 30 and cfg.agent_count == 50
    kinds = {type(s.root) for s in cfg.streams}
    assert kinds == {ClipPlayer, Blend2, Layer, BlendSpace2D, StateMachine}
    crowd = Crowd(cfg)
    crowd.set_trigger(4, "goal")
    for _ in range(3):
        crowd.step()
    assert crowd.state_of(4)
