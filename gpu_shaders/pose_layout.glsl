/* Pose texture layout (DESIGN.md s.3, paper Fig. 2): the only GLSL that knows it.
 * Needs block_layout.glsl before it.
 *
 * Mirrors crowd_addon/core/pose_storage.py (PoseStorage.texel_of_row) and
 * Crowd.agent_rows_index. Logical rows: stream rows `slice * S + stream` with
 * `slice = (F - O) mod M`, then U unique rows (`unique_base + u`), then NT
 * transition-slot rows (`slot_base + k`). A row is 3 * B_max RGBA32F texels, bone
 * major (texel 3 * bone + r is row r of that bone's 3x4 skinning matrix; in the
 * local pose texture the SQT texels (sx, sy, sz, 0), (qw, qx, qy, qz),
 * (tx, ty, tz, 0)), in column blocks of H = texture height rows.
 *
 * Push constants:
 *   ivec4 u_pose_layout  = (H, 3 * B_max, M, S)
 *   ivec4 u_pose_regions = (unique_base, slot_base, F mod M, unused)
 */

#define ANIM_STREAM 0
#define ANIM_UNIQUE 1
#define ANIM_TRANSITION 2

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

/* Logical row of stream `stream` delayed by `offset` frames (0 .. M - 1). */
int stream_pose_row(int stream, int offset)
{
  int slice = u_pose_regions.z - offset; /* both in 0 .. M - 1 */
  if (slice < 0) {
    slice += u_pose_layout.z;
  }
  return slice * u_pose_layout.w + stream;
}

/* Logical row an agent reads this frame from its animation reference
 * (kind: ANIM_*, ref: stream / unique / slot index, offset: frames of delay). */
int agent_pose_row(int kind, int ref, int offset)
{
  if (kind == ANIM_STREAM) {
    return stream_pose_row(ref, offset);
  }
  return (kind == ANIM_UNIQUE ? u_pose_regions.x : u_pose_regions.y) + ref;
}
