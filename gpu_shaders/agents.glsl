/* Per-agent instance data (docs/architecture.md: a row of three RGBA32F texels per agent
 * in `agent_tex`, in column blocks of the texture's height (block_layout.glsl,
 * crowd_addon/gpu/instances.py):
 *   texel 0 = (position x, y, z in metres, heading in radians about +Z)
 *   texel 1 = (kind * 65536 + offset, ref, uniform body scale,
 *              colour as 8-bit r * 65536 + g * 256 + b)
 *   texel 2 = the colours of the agent's palette columns 0..3, each as texel 1's
 *             colour, -1 where the agent has none
 * Small integers are exact in float32. A draw instance is mapped to its agent
 * through `agent_list_tex` (R32I, the agents of one (skeleton, LOD) draw from
 * u_draw.x, crowd_vert.glsl), so one instanced draw serves any subset of the crowd.
 */

struct Agent {
  vec3 position;
  float heading;
  int kind;
  int ref;
  int offset;
  float scale;
  vec3 color;
};

/* An 8-bit colour packed as r * 65536 + g * 256 + b, as RGB in 0..1. */
vec3 unpack_rgb(float code)
{
  int rgb = int(code);
  return vec3((rgb >> 16) & 255, (rgb >> 8) & 255, rgb & 255) / 255.0;
}

int instance_agent(int instance)
{
  int width = textureSize(agent_list_tex, 0).x;
  return texelFetch(agent_list_tex, linear_texel(u_draw.x + instance, width), 0).r;
}

/* The agent record of its first two texels `a`, `b` (however they were read: from
 * agent_tex, or as per-instance attributes gathered from it, agent_gather_comp.glsl). */
Agent agent_from_texels(vec4 a, vec4 b)
{
  int kind_offset = int(b.x);
  Agent r;
  r.position = a.xyz;
  r.heading = a.w;
  r.kind = kind_offset >> 16;
  r.ref = int(b.y);
  r.offset = kind_offset & 65535;
  r.scale = b.z;
  r.color = unpack_rgb(b.w);
  return r;
}

Agent agent_record(int agent)
{
  ivec2 at = block_row_origin(agent, textureSize(agent_tex, 0).y, 3);
  return agent_from_texels(texelFetch(agent_tex, at, 0),
                           texelFetch(agent_tex, at + ivec2(1, 0), 0));
}

/* The agent's palette colour of column `column` (0..3) as packed by agent_record's
 * colour, -1 where it has none; fetched only for vertices of a palette material. */
float agent_palette(int agent, int column)
{
  ivec2 at = block_row_origin(agent, textureSize(agent_tex, 0).y, 3);
  return texelFetch(agent_tex, at + ivec2(2, 0), 0)[column];
}

/* Rotation by the agent's heading about +Z, as (cos, sin). */
vec2 agent_turn(Agent agent)
{
  return vec2(cos(agent.heading), sin(agent.heading));
}

/* A model-space (the skeleton's armature space) direction in world space. */
vec3 turn_z(vec2 turn, vec3 v)
{
  return vec3(turn.x * v.x - turn.y * v.y, turn.y * v.x + turn.x * v.y, v.z);
}
