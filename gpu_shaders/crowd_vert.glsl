/* Instanced crowd skinning: the agents of one (skeleton, LOD) draw.
 * Needs block_layout.glsl, pose_layout.glsl, agents.glsl, skinning.glsl before it.
 *
 * u_draw = (list base, agents in this draw, vertices per mesh copy, copies per
 * instance). Small LOD meshes are drawn as `copies` back-to-back copies per
 * instance (gl_VertexID / vertices picks the copy), so a CPU rasteriser pays its
 * per-instance cost once per several agents; copies past the draw's agent count
 * are moved outside the clip volume. Model space -> world: rotate by the agent's
 * heading about +Z, then move to its position.
 */

void main()
{
  ivec2 copy = divmod(gl_VertexID, u_draw.z);
  int instance = gl_InstanceID * u_draw.w + copy.x;
  if (instance >= u_draw.y) {
    v_world = vec3(0.0);
    v_normal = vec3(0.0, 0.0, 1.0);
    v_color = vec3(0.0);
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
    return;
  }
  Agent agent = agent_record(instance_agent(instance));
  int row = agent_pose_row(agent.kind, agent.ref, agent.offset);
  vec3 p, n;
  skin_vertex(row, bone_idx, bone_w, pos, nor, p, n);
  vec2 turn = agent_turn(agent);
  v_world = turn_z(turn, p) + agent.position;
  v_normal = turn_z(turn, n);
  v_color = agent.color;
  gl_Position = u_view_proj * vec4(v_world, 1.0);
}
