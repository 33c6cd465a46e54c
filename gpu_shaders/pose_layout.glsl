/* Pose texture layout (docs/architecture.md; paper Fig. 2): the only GLSL that knows it.
 * Needs block_layout.glsl before it.
 *
 * Mirrors crowd_addon/core/pose_storage.py (PoseStorage.texel_of_row). Logical rows: stream rows `slice * S + stream` with
 * `slice = (F - O) mod M`, then U unique rows (`unique_base + u`), then NT
 * transition-slot rows (`slot_base + k`). A row is 3 * B_max RGBA32F texels, bone
 * major (texel 3 * bone + r is row r of that bone's 3x4 skinning matrix; in the
 * local-pose texture the ten SQT floats in texels (sx, sy, sz, qw), (qx, qy, qz, tx),
 * (ty, tz, 0, 0)), in column blocks of H = texture height rows.
 *
 * This file maps logical rows to texels; pose_rows.glsl (after it) maps an agent's
 * animation reference to its logical row.
 *
 * Push constant: ivec4 u_pose_layout = (H, 3 * B_max, M, S)
 */

/* Texel coordinate of the first texel of logical row `row`; texel t of the row
 * is at pose_row_origin(row) + ivec2(t, 0). */
ivec2 pose_row_origin(int row)
{
  return block_row_origin(row, u_pose_layout.x, u_pose_layout.y);
}

/* Texel coordinate of texel `texel` (0 .. 3 * B_max - 1) of logical row `row`. */
ivec2 pose_texel(int row, int texel)
{
  return pose_row_origin(row) + ivec2(texel, 0);
}
