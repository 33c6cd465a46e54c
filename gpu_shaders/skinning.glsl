/* Linear blend skinning, paper Eq. 1: v' = sum_i w_i (M_i M_ref_i^-1) v.
 *
 * Each bone's skinning matrix is three RGBA32F texels of the pose row
 * (pose_layout.glsl); the weighted sum of the bones' rows is applied once.
 * Weights are the proxy's influences, strongest first, renormalised to sum 1 on the
 * CPU: `bones`/`weights` hold influences 1..4, `bones2`/`weights2` influences 5..8
 * (read only when INFLUENCES > 4). INFLUENCES (1..8) is how many of them the mesh
 * uses (the rest weigh 0), so a mesh with two influences per vertex fetches six
 * texels, not twelve, and a four-influence mesh does no more work than it ever did.
 */

void blend_bone(ivec2 origin, uint bone, float w, inout vec4 r0, inout vec4 r1,
                inout vec4 r2)
{
  ivec2 at = origin + ivec2(3 * int(bone), 0);
  r0 += w * texelFetch(pose_tex, at, 0);
  r1 += w * texelFetch(pose_tex, at + ivec2(1, 0), 0);
  r2 += w * texelFetch(pose_tex, at + ivec2(2, 0), 0);
}

void skin_vertex(int row, uvec4 bones, vec4 weights, uvec4 bones2, vec4 weights2,
                 vec3 position, vec3 normal, out vec3 skinned_position,
                 out vec3 skinned_normal)
{
  ivec2 origin = pose_row_origin(row);
  vec4 r0 = vec4(0.0), r1 = vec4(0.0), r2 = vec4(0.0);
  for (int i = 0; i < min(INFLUENCES, 4); i++) {
    blend_bone(origin, bones[i], weights[i], r0, r1, r2);
  }
#if INFLUENCES > 4
  for (int i = 0; i < INFLUENCES - 4; i++) {
    blend_bone(origin, bones2[i], weights2[i], r0, r1, r2);
  }
#endif
  vec4 p = vec4(position, 1.0);
  skinned_position = vec3(dot(r0, p), dot(r1, p), dot(r2, p));
  skinned_normal = vec3(dot(r0.xyz, normal), dot(r1.xyz, normal), dot(r2.xyz, normal));
}
