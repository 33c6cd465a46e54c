/* Which logical pose row an agent reads this frame (docs/architecture.md; paper Fig. 2).
 * Needs pose_layout.glsl before it (u_pose_layout). Mirrors Crowd.agent_rows_index.
 *
 * Push constant: ivec4 u_pose_regions = (unique_base, slot_base, F mod M, unused)
 */

#define ANIM_STREAM 0
#define ANIM_UNIQUE 1
#define ANIM_TRANSITION 2

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
