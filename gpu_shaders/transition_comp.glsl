/* Transition slots on the GPU (paper s.4.5, Listing 2), one invocation per slot.
 *
 * Batch entry i of `batch_tex` (RGBA32F, flat) = (slot, target row, S, skeleton):
 * the slot blends its StartP (local-pose row slot_base + slot) towards the target
 * pose (a history or unique row of the same local-pose texture) by S, goes from
 * local to model space through the parent hierarchy (parents precede children),
 * and writes the skinning rows model @ inverse_bind into the pose texture's slot
 * row. `skeleton_tex` has one row per skeleton, four texels per bone: the top
 * three rows of the inverse bind matrix, then (parent, 0, 0, 0); a parent below
 * -1 ends the skeleton. Needs block_layout.glsl, pose_layout.glsl and sqt.glsl first, and
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
  int slot_row = u_pose_regions.y + int(entry.x);
  int target_row = int(entry.y);
  float s = entry.z;
  int skeleton = int(entry.w);
  mat4 model[MAX_BONES];
  for (int b = 0; b < MAX_BONES; b++) {
    int parent = int(texelFetch(skeleton_tex, ivec2(4 * b + 3, skeleton), 0).x);
    if (parent < -1) {
      break;
    }
    Sqt pose = blend_sqt(fetch_local_pose(slot_row, b), fetch_local_pose(target_row, b), s);
    mat4 local = sqt_matrix(pose);
    model[b] = parent < 0 ? local : model[parent] * local;
    mat4 skin = model[b] * inverse_bind(skeleton, b);
    for (int r = 0; r < 3; r++) {
      imageStore(pose_img, pose_texel(slot_row, 3 * b + r),
                 vec4(skin[0][r], skin[1][r], skin[2][r], skin[3][r]));
    }
  }
}
