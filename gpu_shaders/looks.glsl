/* What both look programs read (crowd_addon/gpu/look_data.py): an agent's look state
 * and weight, and a bone's skinning rows. Data:
 *   look_tex: two texels per agent, block-laid like agent_tex:
 *     (target, start, blend, stop) and (lag, skeleton, 0, 0)
 *   look_chain_tex: a row per skeleton: (K, yaw limit, pitch limit, 0),
 *     (forward x, y, 0, 0), per chain bone k (bind pivot xyz, share) and (bone, 0, 0, 0)
 *   look_turn_img / look_turn_tex: LOOK_TURN_TEXELS texels per agent, block-laid: per
 *     chain depth k + 1 the rows [R | t] of the turn that moves a bone at that depth
 *     (look_turns_comp.glsl writes them, look_at.glsl reads them)
 * The frame is u_pose_regions.w. Needs block_layout.glsl and pose_layout.glsl first.
 */

#define LOOK_BONES 8
#define LOOK_TURN_TEXELS 24
#define LOOK_PI 3.14159265358979

/* Texel `texel` (0: state, 1: lag and skeleton) of agent `agent` in look_tex. */
vec4 look_texel(int agent, int texel)
{
  ivec2 at = block_row_origin(agent, textureSize(look_tex, 0).y, 2);
  return texelFetch(look_tex, at + ivec2(texel, 0), 0);
}

/* AgentLooks.weights at frame u_pose_regions.w of state (target, start, blend, stop). */
float look_weight(vec4 state)
{
  if (state.x < 0.0) {
    return 0.0;
  }
  float frame = float(u_pose_regions.w);
  float up = state.z > 0.0 ? (frame - state.y) / state.z : (frame >= state.y ? 1.0 : 0.0);
  float down = state.z > 0.0 ? (frame - state.w) / state.z : (frame >= state.w ? 1.0 : 0.0);
  return clamp(up, 0.0, 1.0) * (1.0 - clamp(down, 0.0, 1.0));
}

/* Rows of bone `bone`'s skinning matrix in the pose row at `origin`. */
void look_bone_rows(ivec2 origin, int bone, out vec4 r0, out vec4 r1, out vec4 r2)
{
  ivec2 at = origin + ivec2(3 * bone, 0);
  r0 = texelFetch(pose_tex, at, 0);
  r1 = texelFetch(pose_tex, at + ivec2(1, 0), 0);
  r2 = texelFetch(pose_tex, at + ivec2(2, 0), 0);
}
