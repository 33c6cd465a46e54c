/* Textures of fixed-size rows laid out in column blocks (docs/architecture.md, Conventions), and
 * textures used as flat arrays. No uniforms: the callers pass the geometry.
 *
 * A block-laid texture holds logical rows of `row_texels` texels; row r starts at
 * texel ((r / H) * row_texels, r % H), H = the texture height, so rows past the
 * height wrap into column blocks side by side. The pose texture, the local pose
 * texture (crowd_addon/core/pose_storage.py) and the agent texture
 * (crowd_addon/gpu/instances.py) all use it.
 */

/* (a / b, a % b) for 0 <= a < 2^24 and b > 0, exactly. Through float division
 * and one correction step, because CPU rasterisers (Mesa llvmpipe) have no vector
 * integer division and run it lane by lane. */
ivec2 divmod(int a, int b)
{
  int q = int((float(a) + 0.5) / float(b));
  int r = a - q * b;
  if (r < 0) {
    q -= 1;
    r += b;
  }
  else if (r >= b) {
    q += 1;
    r -= b;
  }
  return ivec2(q, r);
}

/* Texel coordinate of the first texel of logical row `row`. */
ivec2 block_row_origin(int row, int block_rows, int row_texels)
{
  ivec2 block = divmod(row, block_rows);
  return ivec2(block.x * row_texels, block.y);
}

/* Texel `index` of a texture used as a flat array, `width` texels per row. */
ivec2 linear_texel(int index, int width)
{
  return divmod(index, width).yx;
}
