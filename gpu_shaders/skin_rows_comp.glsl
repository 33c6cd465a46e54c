/* Skinning rows on the GPU (paper s.4.5, Listing 2), one invocation per batch entry.
 *
 * With GPU skinning the CPU uploads only local poses (the local-pose texture
 * `local_tex`, same geometry as the pose texture) and this shader writes the
 * skinning rows. Batch entry i of `batch_tex` (RGBA32F, flat) is
 * (row, source row, S, skeleton): the local pose of `row` blends towards that of
 * `source` by S -- a transition slot's StartP towards its target (a history or
 * unique row); a stream or unique row is its own source with S = 1 -- goes from
 * local to model space through the parent hierarchy (parents precede children),
 * and the skinning rows model @ inverse_bind land in the pose texture's `row`.
 * `skeleton_tex` has one row per skeleton, four texels per bone: the top three
 * rows of the inverse bind matrix, then (parent, 0, 0, 0); a parent below -1 ends
 * the skeleton. Needs block_layout.glsl, pose_layout.glsl and sqt.glsl first, and
 * MAX_BONES (B_max) defined.
 */

mat4 inverse_bind(int skeleton, int bone)
{
  vec4 r0 = texelFetch(skeleton_tex, ivec2(4 * bone, skeleton), 0);
  vec4 r1 = texelFetch(skeleton_tex, ivec2(4 * bone + 1, skeleton), 0);
  vec4 r2 = texelFetch(skeleton_tex, ivec2(4 * bone + 2, skeleton), 0);
  return transpose(mat4(r0, r1, r2, vec4(0.0, 0.0, 0.0, 1.0)));
}

void main()
{
  int i = int(gl_GlobalInvocationID.x);
  if (i >= u_batch_count) {
    return;
  }
  vec4 entry = texelFetch(batch_tex, linear_texel(i, textureSize(batch_tex, 0).x), 0);
  int row = int(entry.x);
  int source = int(entry.y);
  float s = entry.z;
  int skeleton = int(entry.w);
  mat4 model[MAX_BONES];
  for (int b = 0; b < MAX_BONES; b++) {
    int parent = int(texelFetch(skeleton_tex, ivec2(4 * b + 3, skeleton), 0).x);
    if (parent < -1) {
      break;
    }
    Sqt pose = blend_sqt(fetch_local_pose(row, b), fetch_local_pose(source, b), s);
    mat4 local = sqt_matrix(pose);
    model[b] = parent < 0 ? local : model[parent] * local;
    mat4 skin = model[b] * inverse_bind(skeleton, b);
    for (int r = 0; r < 3; r++) {
      imageStore(pose_img, pose_texel(row, 3 * b + r),
                 vec4(skin[0][r], skin[1][r], skin[2][r], skin[3][r]));
    }
  }
}
