/* Look-at in the vertex stage: crowd_addon/core/look_at.py (look_turns, apply_look) on
 * the GPU, from the agent's look state, its pose row and the frame; nothing per agent
 * per frame on the CPU. Data (crowd_addon/gpu/look_data.py):
 *   look_tex: two texels per agent, block-laid like agent_tex:
 *     (target, start, blend, stop) and (lag, skeleton, 0, 0)
 *   look_target_tex: row 0 per target (first frame, frames, rows, first row), then
 *     its smoothed path, `width` frames a row
 *   look_chain_tex: a row per skeleton: (K, yaw limit, pitch limit, depth column),
 *     (forward x, y, 0, 0), per chain bone k (bind pivot xyz, share) and (bone, 0, 0, 0),
 *     from the depth column per bone its chain depth
 * The frame is u_pose_regions.w. Needs block_layout.glsl, pose_layout.glsl,
 * agents.glsl and skinning.glsl before it.
 *
 * A vertex of an agent whose weight is 0 pays one texel fetch; of a looking agent,
 * one depth fetch per influence; only a vertex bound to a bone at or below the chain
 * works out the chain's turns (the agent's head direction, the clamped yaw and
 * pitch, the turn Q shared along the chain), the same for every such vertex of the
 * agent, in float32: Q's angle from its quaternion (atan, well conditioned near 0,
 * where core's arccos of the trace in float64 needs no care).
 */

#define LOOK_BONES 8
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

/* Crowd.look_targets_model: target `target` read `lag` frames late, in the agent's
 * model space (its position, heading and scale undone). */
vec3 look_target_model(Agent agent, int target, int lag)
{
  vec4 head = texelFetch(look_target_tex, ivec2(target, 0), 0);
  int i = clamp(u_pose_regions.w - lag - int(head.x), 0, int(head.y) - 1);
  ivec2 at = linear_texel(i, textureSize(look_target_tex, 0).x) + ivec2(0, int(head.w));
  vec3 d = texelFetch(look_target_tex, at, 0).xyz - agent.position;
  float c = cos(agent.heading), s = sin(agent.heading);
  return vec3(c * d.x + s * d.y, c * d.y - s * d.x, d.z) / agent.scale;
}

/* Rows of bone `bone`'s skinning matrix in the pose row at `origin`. */
void look_bone_rows(ivec2 origin, int bone, out vec4 r0, out vec4 r1, out vec4 r2)
{
  ivec2 at = origin + ivec2(3 * bone, 0);
  r0 = texelFetch(pose_tex, at, 0);
  r1 = texelFetch(pose_tex, at + ivec2(1, 0), 0);
  r2 = texelFetch(pose_tex, at + ivec2(2, 0), 0);
}

/* Rotation about unit `axis` by `angle` (core.look_at._axis_angle). */
mat3 look_axis_angle(vec3 axis, float angle)
{
  float c = cos(angle), s = sin(angle), t = 1.0 - c;
  float x = axis.x, y = axis.y, z = axis.z;
  return mat3(vec3(t * x * x + c, t * x * y + s * z, t * x * z - s * y),
              vec3(t * x * y - s * z, t * y * y + c, t * y * z + s * x),
              vec3(t * x * z + s * y, t * y * z - s * x, t * z * z + c));
}

/* (yaw, pitch) of `v` from the forward axis `fwd` (left = Z x fwd). */
vec2 look_yaw_pitch(vec3 v, vec3 fwd, vec3 left)
{
  float a = dot(v, left), b = dot(v, fwd);
  return vec2(atan(a, b), atan(v.z, length(vec2(a, b))));
}

/* The chain's turns (look_turns, then apply_look's products) of chain bones 0 ..
 * `count` - 1: rot[k], shift[k] move a bone at chain depth k + 1. */
void look_chain(int skeleton, int count, ivec2 origin, Agent agent, vec4 state,
                int lag, float weight, out mat3 rot[LOOK_BONES], out vec3 shift[LOOK_BONES])
{
  vec4 header = texelFetch(look_chain_tex, ivec2(0, skeleton), 0);
  int k = int(header.x);
  vec3 fwd = vec3(texelFetch(look_chain_tex, ivec2(1, skeleton), 0).xy, 0.0);
  vec3 left = vec3(-fwd.y, fwd.x, 0.0);
  vec4 r0, r1, r2;
  /* the head: its pivot and where it faces */
  vec4 pivot_share = texelFetch(look_chain_tex, ivec2(2 * k, skeleton), 0);
  int bone = int(texelFetch(look_chain_tex, ivec2(2 * k + 1, skeleton), 0).x);
  look_bone_rows(origin, bone, r0, r1, r2);
  vec4 q = vec4(pivot_share.xyz, 1.0);
  vec3 pivot = vec3(dot(r0, q), dot(r1, q), dot(r2, q));
  vec3 f = normalize(vec3(dot(r0.xyz, fwd), dot(r1.xyz, fwd), dot(r2.xyz, fwd)));
  vec3 d = look_target_model(agent, int(state.x), lag) - pivot;
  d /= max(length(d), 1e-9);
  vec2 from = look_yaw_pitch(f, fwd, left);
  vec2 to = look_yaw_pitch(d, fwd, left);
  to = clamp(to, -header.yz, header.yz);
  float dyaw = weight * (mod(to.x - from.x + LOOK_PI, 2.0 * LOOK_PI) - LOOK_PI);
  float dpitch = weight * (to.y - from.y);
  /* Q = yaw about +Z after pitch about the head's horizontal right axis, as a
   * quaternion (w, v), then as axis and angle */
  vec3 right = vec3(f.y, -f.x, 0.0);
  float norm = length(right);
  right = norm > 1e-9 ? right / norm : left;
  float cy = cos(0.5 * dyaw), sy = sin(0.5 * dyaw);
  float cp = cos(0.5 * dpitch), sp = sin(0.5 * dpitch);
  vec3 v = cy * sp * right + vec3(0.0, 0.0, cp * sy) + sy * sp * vec3(-right.y, right.x, 0.0);
  float vn = length(v);
  float angle = 2.0 * atan(vn, cy * cp);
  vec3 axis = vn > 1e-12 ? v / vn : vec3(0.0, 0.0, 1.0);
  /* shared along the chain, each bone about its pivot as moved by those above */
  mat3 mr = mat3(1.0);
  vec3 mt = vec3(0.0);
  for (int i = 0; i < LOOK_BONES; i++) {
    if (i >= count) {
      break;
    }
    pivot_share = texelFetch(look_chain_tex, ivec2(2 + 2 * i, skeleton), 0);
    bone = int(texelFetch(look_chain_tex, ivec2(3 + 2 * i, skeleton), 0).x);
    look_bone_rows(origin, bone, r0, r1, r2);
    q = vec4(pivot_share.xyz, 1.0);
    vec3 p = mr * vec3(dot(r0, q), dot(r1, q), dot(r2, q)) + mt;
    mat3 r = look_axis_angle(axis, angle * pivot_share.w);
    mr = r * mr;
    mt = r * mt + (p - r * p);
    rot[i] = mr;
    shift[i] = mt;
  }
}

/* Chain depth of each of four bones (0 past INFLUENCES or off the chain). */
ivec4 look_depths(int skeleton, int column, uvec4 bones, int first)
{
  ivec4 depth = ivec4(0);
  for (int i = 0; i < 4; i++) {
    if (first + i < INFLUENCES) {
      depth[i] = int(texelFetch(look_chain_tex, ivec2(column + int(bones[i]), skeleton), 0).x);
    }
  }
  return depth;
}

/* Bone `bone`'s rows, moved by (R, T) when `depth` > 0, weighted into r0..r2. */
void look_blend_bone(ivec2 origin, uint bone, float w, int depth, mat3 rot[LOOK_BONES],
                     vec3 shift[LOOK_BONES], inout vec4 r0, inout vec4 r1, inout vec4 r2)
{
  vec4 a0, a1, a2;
  look_bone_rows(origin, int(bone), a0, a1, a2);
  if (depth > 0) {
    mat3 m = rot[depth - 1];
    vec3 t = shift[depth - 1];
    vec4 b0 = m[0][0] * a0 + m[1][0] * a1 + m[2][0] * a2 + vec4(0.0, 0.0, 0.0, t.x);
    vec4 b1 = m[0][1] * a0 + m[1][1] * a1 + m[2][1] * a2 + vec4(0.0, 0.0, 0.0, t.y);
    vec4 b2 = m[0][2] * a0 + m[1][2] * a1 + m[2][2] * a2 + vec4(0.0, 0.0, 0.0, t.z);
    a0 = b0;
    a1 = b1;
    a2 = b2;
  }
  r0 += w * a0;
  r1 += w * a1;
  r2 += w * a2;
}

/* skin_vertex with the agent's look applied (Crowd.agent_rows): `state` its look
 * texel 0, `weight` > 0 its look weight now. */
void skin_vertex_looking(int agent_id, Agent agent, vec4 state, float weight, int row,
                         uvec4 bones, vec4 weights, uvec4 bones2, vec4 weights2,
                         vec3 position, vec3 normal, out vec3 skinned_position,
                         out vec3 skinned_normal)
{
  vec4 lag_skeleton = look_texel(agent_id, 1);
  int skeleton = int(lag_skeleton.y);
  vec4 header = texelFetch(look_chain_tex, ivec2(0, skeleton), 0);
  int column = int(header.w);
  ivec4 depth = int(header.x) > 0 ? look_depths(skeleton, column, bones, 0) : ivec4(0);
  ivec4 depth2 = ivec4(0);
#if INFLUENCES > 4
  if (int(header.x) > 0) {
    depth2 = look_depths(skeleton, column, bones2, 4);
  }
#endif
  ivec4 deepest4 = max(depth, depth2);
  int deepest = max(max(deepest4.x, deepest4.y), max(deepest4.z, deepest4.w));
  if (deepest == 0) {
    skin_vertex(row, bones, weights, bones2, weights2, position, normal, skinned_position,
                skinned_normal);
    return;
  }
  ivec2 origin = pose_row_origin(row);
  mat3 rot[LOOK_BONES];
  vec3 shift[LOOK_BONES];
  look_chain(skeleton, deepest, origin, agent, state, int(lag_skeleton.x), weight, rot, shift);
  vec4 r0 = vec4(0.0), r1 = vec4(0.0), r2 = vec4(0.0);
  for (int i = 0; i < min(INFLUENCES, 4); i++) {
    look_blend_bone(origin, bones[i], weights[i], depth[i], rot, shift, r0, r1, r2);
  }
#if INFLUENCES > 4
  for (int i = 0; i < INFLUENCES - 4; i++) {
    look_blend_bone(origin, bones2[i], weights2[i], depth2[i], rot, shift, r0, r1, r2);
  }
#endif
  vec4 p = vec4(position, 1.0);
  skinned_position = vec3(dot(r0, p), dot(r1, p), dot(r2, p));
  skinned_normal = vec3(dot(r0.xyz, normal), dot(r1.xyz, normal), dot(r2.xyz, normal));
}
