/* The crowd vertex: the current vertex (`pos`, `nor`, `bone_idx`, `bone_w`, and with
 * INFLUENCES > 4 `bone_idx2`, `bone_w2`: programs.for_influences declares them) of agent
 * `agent_id` skinned from its pose row (paper Eq. 1) and placed in the world --
 * rotated by the agent's heading about +Z, then moved to its position -- into the
 * stage outputs v_world, v_normal, v_color. One function for every vertex stage that
 * draws or captures the crowd (crowd_vert.glsl, capture_vert.glsl), so they cannot
 * disagree. Needs block_layout.glsl, pose_layout.glsl, pose_rows.glsl, agents.glsl
 * and skinning.glsl before it.
 */

void crowd_vertex(int agent_id)
{
  Agent agent = agent_record(agent_id);
  int row = agent_pose_row(agent.kind, agent.ref, agent.offset);
  vec3 p, n;
#if INFLUENCES > 4
  skin_vertex(row, bone_idx, bone_w, bone_idx2, bone_w2, pos, nor, p, n);
#else
  skin_vertex(row, bone_idx, bone_w, uvec4(0u), vec4(0.0), pos, nor, p, n);
#endif
  vec2 turn = agent_turn(agent);
  v_world = turn_z(turn, p) + agent.position;
  v_normal = turn_z(turn, n);
  v_color = agent.color;
}
