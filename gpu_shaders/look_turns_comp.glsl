/* The look's turns of every looking agent, once a frame (look_turns.glsl), into
 * look_turn_img for the vertex stage (look_at.glsl): one invocation per agent; an agent
 * whose look weight is 0, or whose skeleton has no look chain, writes nothing (the
 * vertex stage does not read it then). u_looks.x: the agent count.
 */

void main()
{
  int id = int(gl_GlobalInvocationID.x);
  if (id >= u_looks.x) {
    return;
  }
  vec4 state = look_texel(id, 0);
  float weight = look_weight(state);
  if (weight <= 0.0) {
    return;
  }
  vec4 lag_skeleton = look_texel(id, 1);
  int skeleton = int(lag_skeleton.y);
  int count = min(int(texelFetch(look_chain_tex, ivec2(0, skeleton), 0).x), LOOK_BONES);
  if (count == 0) {
    return;
  }
  Agent agent = agent_record(id);
  int row = agent_pose_row(agent.kind, agent.ref, agent.offset);
  mat3 rot[LOOK_BONES];
  vec3 shift[LOOK_BONES];
  look_chain(skeleton, count, pose_row_origin(row), agent, state, int(lag_skeleton.x),
             weight, rot, shift);
  ivec2 at = block_row_origin(id, imageSize(look_turn_img).y, LOOK_TURN_TEXELS);
  for (int k = 0; k < LOOK_BONES; k++) {
    if (k >= count) {
      break;
    }
    for (int i = 0; i < 3; i++) {
      imageStore(look_turn_img, at + ivec2(3 * k + i, 0),
                 vec4(rot[k][0][i], rot[k][1][i], rot[k][2][i], shift[k][i]));
    }
  }
}
