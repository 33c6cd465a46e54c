/* Integer texture upload for the Blender backend (its Python GPUTexture takes only
 * float data): `source_tex` (R32F, values exact integers below 2^24) is written to
 * `target_img` (R32I) at texel offset `u_offset`. One invocation per source texel.
 */

void main()
{
  ivec2 id = ivec2(gl_GlobalInvocationID.xy);
  if (any(greaterThanEqual(id, textureSize(source_tex, 0)))) {
    return;
  }
  imageStore(target_img, u_offset + id, ivec4(int(texelFetch(source_tex, id, 0).r)));
}
