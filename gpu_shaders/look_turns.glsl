/* The look's turns (crowd_addon/core/runtime/look_at.py: look_turns, then apply_look's
 * products) worked out once per looking agent and frame, not per vertex: the agent's
 * head direction, the clamped yaw and pitch, the turn Q shared along the chain, in
 * float32: Q's angle from its quaternion (atan, well conditioned near 0, where core's
 * arccos of the trace in float64 needs no care). look_target_tex: row 0 per target
 * (first frame, frames, rows, first row), then its smoothed path, `width` frames a row.
 * Needs looks.glsl and agents.glsl before it.
 */

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
