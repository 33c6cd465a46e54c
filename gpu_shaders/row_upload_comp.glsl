/* Writes staged rows into a block-laid texture (block_layout.glsl), for backends
 * that cannot update part of a texture from the CPU (Blender's gpu module): the
 * dirty rows of a frame are staged in a small texture, one row of
 * u_upload.y texels per staged row, and `row_index_tex` (R32I, flat) names each
 * staged row's logical row in the destination. One invocation per texel.
 *
 * u_upload = (destination block rows H, texels a row, staged rows, unused).
 */

void main()
{
  ivec2 at = ivec2(gl_GlobalInvocationID.xy); /* (texel in the row, staged row) */
  if (at.x >= u_upload.y || at.y >= u_upload.z) {
    return;
  }
  int row = texelFetch(row_index_tex, linear_texel(at.y, textureSize(row_index_tex, 0).x),
                       0).r;
  imageStore(dest_img, block_row_origin(row, u_upload.x, u_upload.y) + ivec2(at.x, 0),
             texelFetch(staging_tex, at, 0));
}
