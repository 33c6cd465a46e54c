/* The draw lists' agent records as per-instance vertex attributes (moderngl only,
 * crowd_vertex.glsl's AGENT_ATTRIBUTES): one invocation per draw list entry
 * i < u_draw.y writes AGENT_RECORD_TEXELS vec4 from records[AGENT_RECORD_TEXELS * i]:
 * the agent's three agent_tex texels (placement; reference, scale and colour;
 * palette) and its look state (look_tex texel 0), and its id to record_ids[i] (an
 * int buffer of its own: no int travels as a float's bits). A draw then binds both
 * from its list base on. Needs block_layout.glsl and agents.glsl before it
 * (u_draw = (0, entries, 0, 0)).
 */

#define AGENT_RECORD_TEXELS 4

void main()
{
  int i = int(gl_GlobalInvocationID.x);
  if (i >= u_draw.y) {
    return;
  }
  int agent = instance_agent(i);
  ivec2 at = block_row_origin(agent, textureSize(agent_tex, 0).y, 3);
  int out_at = AGENT_RECORD_TEXELS * i;
  records[out_at] = texelFetch(agent_tex, at, 0);
  records[out_at + 1] = texelFetch(agent_tex, at + ivec2(1, 0), 0);
  records[out_at + 2] = texelFetch(agent_tex, at + ivec2(2, 0), 0);
  records[out_at + 3] = texelFetch(look_tex,
                                   block_row_origin(agent, textureSize(look_tex, 0).y, 2), 0);
  record_ids[i] = agent;
}
