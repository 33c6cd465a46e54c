/* The crowd vertex: the current vertex (`pos`, `nor`, `bone_idx`, `bone_w`, `col`, and with
 * INFLUENCES > 4 `bone_idx2`, `bone_w2`: programs.for_influences declares them) of agent
 * `agent_id` skinned from its pose row (paper Eq. 1) and placed in the world --
 * scaled by the agent's scale, rotated by its heading about +Z, then moved to its
 * position -- into the
 * stage outputs v_world, v_normal, v_color. The colour is the vertex's material colour
 * `col` tinted by the agent's colour where that material is unsaturated (white, grey:
 * a shirt takes the team colour, skin and dyed cloth keep theirs; a mesh without
 * materials is white, so the agent's colour alone), or, where the agent's palette
 * colours that material (column `col.a`, 255: none), the agent's palette colour.
 * One function for every vertex stage that
 * draws or captures the crowd (crowd_vert.glsl, capture_vert.glsl), so they cannot
 * disagree. An agent that looks at something (look_at.glsl) is skinned from its
 * pose row with its look applied. Needs block_layout.glsl, pose_layout.glsl,
 * pose_rows.glsl, agents.glsl, skinning.glsl and look_at.glsl before it.
 */

/* `base` tinted by `tint` in proportion to how grey it is: saturation 0 takes the tint
 * fully, 0.25 and above not at all. */
vec3 agent_tint(vec3 base, vec3 tint)
{
  float high = max(base.r, max(base.g, base.b));
  float low = min(base.r, min(base.g, base.b));
  float saturation = (high - low) / max(high, 1e-4);
  return mix(base, base * tint, clamp(1.0 - 4.0 * saturation, 0.0, 1.0));
}

/* LOOKS 0 leaves the look out: for a frame where no agent looks (LookData.active).
 * A branch on a per-vertex value is run by llvmpipe for every vertex, lanes masked,
 * so the look path cost every vertex ~2.5x its skinning even with no look on. */
#ifndef LOOKS
#define LOOKS 1
#endif

/* AGENT_ATTRIBUTES 1: the agent's texels come as per-instance vertex attributes
 * (agent_in0..agent_in3 and agent_in_id, programs.AGENT_INPUTS: its two agent_tex
 * texels, its palette texel, its look state texel and its id), gathered once a frame
 * from agent_tex, look_tex and the draw list (agent_gather_comp.glsl), instead of read
 * from those textures by every vertex (moderngl only: Blender's gpu module has no
 * per-instance attributes). The values, so the pictures, are the same. */
#ifndef AGENT_ATTRIBUTES
#define AGENT_ATTRIBUTES 0
#endif

void crowd_vertex(int agent_id)
{
#if AGENT_ATTRIBUTES
  Agent agent = agent_from_texels(agent_in0, agent_in1);
#else
  Agent agent = agent_record(agent_id);
#endif
  int row = agent_pose_row(agent.kind, agent.ref, agent.offset);
  vec3 p, n;
#if INFLUENCES > 4
  uvec4 bones2 = bone_idx2;
  vec4 weights2 = bone_w2;
#else
  uvec4 bones2 = uvec4(0u);
  vec4 weights2 = vec4(0.0);
#endif
#if LOOKS
#if AGENT_ATTRIBUTES
  vec4 look = agent_in3;
#else
  vec4 look = look_texel(agent_id, 0);
#endif
  float weight = look_weight(look);
  if (weight > 0.0) {
    skin_vertex_looking(agent_id, row, look_depth, bone_idx, bone_w, bones2, weights2, pos,
                        nor, p, n);
  }
  else {
    skin_vertex(row, bone_idx, bone_w, bones2, weights2, pos, nor, p, n);
  }
#else
  skin_vertex(row, bone_idx, bone_w, bones2, weights2, pos, nor, p, n);
#endif
  vec2 turn = agent_turn(agent);
  v_world = turn_z(turn, p * agent.scale) + agent.position;
  v_normal = turn_z(turn, n);
  v_color = agent_tint(col.rgb, agent.color);
  int column = int(col.a * 255.0 + 0.5);
  if (column < 4) {
#if AGENT_ATTRIBUTES
    float code = agent_in2[column];
#else
    float code = agent_palette(agent_id, column);
#endif
    if (code >= 0.0)
      v_color = unpack_rgb(code);
  }
}
