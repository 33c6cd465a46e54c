/* Look-at in the vertex stage (crowd_addon/core/runtime/looks.py turn_rows on the GPU):
 * a vertex of an agent whose weight is 0 pays one texel fetch; of a looking agent, a
 * vertex off the chain (its look_depth 0) skins as any other, and one on or below it
 * reads, per influence the look turns, that depth's turn from look_turn_tex (three
 * texels: look_turns_comp.glsl worked it out once for the agent this frame). Needs
 * looks.glsl and skinning.glsl before it.
 */

/* Rows [R | t] of the turn of chain depth `depth` (1..K) of agent `agent_id`. */
void look_turn(int agent_id, int depth, out vec4 t0, out vec4 t1, out vec4 t2)
{
  ivec2 at = block_row_origin(agent_id, textureSize(look_turn_tex, 0).y, LOOK_TURN_TEXELS)
             + ivec2(3 * (depth - 1), 0);
  t0 = texelFetch(look_turn_tex, at, 0);
  t1 = texelFetch(look_turn_tex, at + ivec2(1, 0), 0);
  t2 = texelFetch(look_turn_tex, at + ivec2(2, 0), 0);
}

/* Bone `bone`'s rows, moved by its depth's turn when `depth` > 0, weighted into r0..r2. */
void look_blend_bone(int agent_id, ivec2 origin, uint bone, float w, int depth,
                     inout vec4 r0, inout vec4 r1, inout vec4 r2)
{
  vec4 a0, a1, a2;
  look_bone_rows(origin, int(bone), a0, a1, a2);
  if (depth > 0) {
    vec4 t0, t1, t2;
    look_turn(agent_id, depth, t0, t1, t2);
    vec4 b0 = t0.x * a0 + t0.y * a1 + t0.z * a2 + vec4(0.0, 0.0, 0.0, t0.w);
    vec4 b1 = t1.x * a0 + t1.y * a1 + t1.z * a2 + vec4(0.0, 0.0, 0.0, t1.w);
    vec4 b2 = t2.x * a0 + t2.y * a1 + t2.z * a2 + vec4(0.0, 0.0, 0.0, t2.w);
    a0 = b0;
    a1 = b1;
    a2 = b2;
  }
  r0 += w * a0;
  r1 += w * a1;
  r2 += w * a2;
}

/* skin_vertex with the agent's look applied (Crowd.agent_rows): `depths`, the vertex's
 * look_depth, holds each influence's chain depth in four bits (0: the look leaves
 * it), so a vertex off the chain skins as any other. */
void skin_vertex_looking(int agent_id, int row, uint depths, uvec4 bones, vec4 weights,
                         uvec4 bones2, vec4 weights2, vec3 position, vec3 normal,
                         out vec3 skinned_position, out vec3 skinned_normal)
{
  if (depths == 0u) {
    skin_vertex(row, bones, weights, bones2, weights2, position, normal, skinned_position,
                skinned_normal);
    return;
  }
  ivec2 origin = pose_row_origin(row);
  vec4 r0 = vec4(0.0), r1 = vec4(0.0), r2 = vec4(0.0);
  for (int i = 0; i < min(INFLUENCES, 4); i++) {
    int depth = int((depths >> uint(4 * i)) & 15u);
    look_blend_bone(agent_id, origin, bones[i], weights[i], depth, r0, r1, r2);
  }
#if INFLUENCES > 4
  for (int i = 0; i < INFLUENCES - 4; i++) {
    int depth = int((depths >> uint(4 * (i + 4))) & 15u);
    look_blend_bone(agent_id, origin, bones2[i], weights2[i], depth, r0, r1, r2);
  }
#endif
  vec4 p = vec4(position, 1.0);
  skinned_position = vec3(dot(r0, p), dot(r1, p), dot(r2, p));
  skinned_normal = vec3(dot(r0.xyz, normal), dot(r1.xyz, normal), dot(r2.xyz, normal));
}
