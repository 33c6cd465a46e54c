"""The memory model and a stream/offset plan (:mod:`.budget`) as a readable report.

What ``crowd budget`` prints: :func:`report` gives the text (one line per quantity of
the paper's model, then the plan), :func:`report_dict` the same as plain values for
JSON. Sizes are bytes; lengths are frames.
"""

from __future__ import annotations

import dataclasses

from . import budget as b
from .budget import BudgetPlan, MemoryModel

__all__ = ["report", "report_dict"]


def report_dict(model: MemoryModel, plan: BudgetPlan, *, budget_mb: float, unit_bytes: int,
                max_offset_source: str) -> dict:
    """The report as a JSON-ready dict: units (``budget_mb`` MB of ``unit_bytes`` bytes
    each), where M came from, the model and the plan."""
    return {"units": {"size": "bytes", "length": "frames", "budget_unit_bytes": unit_bytes,
                      "budget_mb": budget_mb},
            "max_offset_source": max_offset_source,
            "memory_model": dataclasses.asdict(model),
            "plan": dataclasses.asdict(plan)}


def report(model: MemoryModel, plan: BudgetPlan, *, budget_mb: float, unit_name: str,
           pose_source: str, max_offset_source: str, clip_count: int, bones: int,
           gpu_bytes_per_bone: float, fps: float) -> str:
    """The report as text.

    budget_mb, unit_name : the budget as given (e.g. ``520``, ``"MB"``).
    pose_source, max_offset_source : where PoseSize and M came from (shown in brackets).
    clip_count : clips averaged into MotionLength. bones, gpu_bytes_per_bone, fps : the
    plan's GPU pose row and frame rate.
    """
    lines = [
        f"Paper memory model (Paduraru s.5), MemBudget {budget_mb:g} {unit_name} "
        f"= {model.budget_bytes:,.0f} B",
        f"  PoseSize                {model.pose_bytes:,.6g} B ({pose_source})",
        f"  MotionLength            {model.motion_length:,.6g} frames "
        f"(mean of {clip_count} clip{'s' if clip_count != 1 else ''})",
        f"  M                       {model.max_offset} frames ({max_offset_source})",
        f"  ClipSize_OLD            {model.clip_size_old:,.6g} B",
        f"  ClipSize_NEW            {model.clip_size_new:,.6g} B",
        f"  NumClips_OLD            {model.num_clips_old:,}  floor(MemBudget / ClipSize_OLD)",
        f"  NumClips_NEW            {model.num_clips_new:,}  "
        "floor(MotionLength / M x NumClips_OLD), the paper's formula",
        f"  MemBudget/ClipSize_NEW  {model.num_clips_new_direct:,}  "
        "floor(MemBudget / ClipSize_NEW), direct",
        f"  (the paper prints NumClips_OLD {b.PAPER_NUM_CLIPS_OLD} and NumClips_NEW "
        f"{b.PAPER_NUM_CLIPS_NEW:,} for its inputs; its 216 does not follow from them, "
        "see docs/performance_budget.md)",
        "",
        f"Plan for {plan.agents:,} agents (GPU pose row: {bones} bones x "
        f"{gpu_bytes_per_bone:g} B = {plan.row_bytes:,} B)",
        f"  streams S               {plan.streams:,} (budget allows up to "
        f"{plan.max_streams:,} at this M)",
        f"  max offset M            {plan.max_offset} frames = "
        f"{plan.offset_seconds:.2f} s at {fps:g} fps",
        f"  agents per stream       {plan.agents_per_stream:,.1f}",
        f"  agents per key          {plan.agents_per_key:.2f} per (stream, offset), "
        f"target <= {plan.target_agents_per_key:g}: "
        f"{'met' if plan.meets_target else 'NOT met'}",
        f"  rows                    {plan.history_rows:,} history + "
        f"{plan.unique_agents:,} unique + {plan.transition_slots:,} transition "
        f"= {plan.total_rows:,}",
        f"  bytes used              {plan.bytes_used:,} B of {plan.budget_bytes:,.0f} B "
        f"({100.0 * plan.bytes_used / plan.budget_bytes:.1f} %)",
        f"  upload per frame        {plan.stream_upload_bytes:,} B (S rows); "
        f"{plan.peak_upload_bytes:,} B with every unique and transition row",
    ]
    lines += [f"  note: {note}" for note in plan.notes]
    return "\n".join(lines)
