/* Vertex capture for read-back without transform feedback (the Blender backend):
 * the crowd vertex of crowd_vert.glsl for one agent per instance (same library
 * calls, in the same order), drawn as a point on pixel (gl_VertexID,
 * gl_InstanceID) of an RGBA32F target of u_capture_size pixels, where
 * capture_frag.glsl writes v_world. u_draw = (list base, agents, unused, unused).
 * Needs block_layout.glsl, pose_layout.glsl, agents.glsl, skinning.glsl before it.
 */

void main()
{
  Agent agent = agent_record(instance_agent(gl_InstanceID));
  int row = agent_pose_row(agent.kind, agent.ref, agent.offset);
  vec3 p, n;
  skin_vertex(row, bone_idx, bone_w, pos, nor, p, n);
  vec2 turn = agent_turn(agent);
  v_world = turn_z(turn, p) + agent.position;
  v_normal = turn_z(turn, n);
  v_color = agent.color;
  vec2 pixel = vec2(gl_VertexID, gl_InstanceID) + 0.5;
  gl_Position = vec4(pixel / vec2(u_capture_size) * 2.0 - 1.0, 0.0, 1.0);
}
