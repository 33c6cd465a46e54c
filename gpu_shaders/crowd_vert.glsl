/* Instanced crowd skinning: the agents of one (skeleton, LOD) draw.
 * Needs crowd_vertex.glsl and its libraries before it.
 *
 * u_draw = (list base, agents in this draw, vertices per mesh copy, copies per
 * instance). Small LOD meshes are drawn as `copies` back-to-back copies per
 * instance (gl_VertexID / vertices picks the copy), so a CPU rasteriser pays its
 * per-instance cost once per several agents; copies past the draw's agent count
 * are moved outside the clip volume. With AGENT_ATTRIBUTES (crowd_vertex.glsl) the
 * draw's agents come as per-instance attributes, one an instance.
 */

void main()
{
#if AGENT_ATTRIBUTES
  crowd_vertex(agent_in_id);            /* one agent an instance: copies are 1 */
#else
  ivec2 copy = divmod(gl_VertexID, u_draw.z);
  int instance = gl_InstanceID * u_draw.w + copy.x;
  if (instance >= u_draw.y) {
    v_world = vec3(0.0);
    v_shadow = vec3(0.0);
    v_normal = vec3(0.0, 0.0, 1.0);
    v_color = vec3(0.0);
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
    return;
  }
  crowd_vertex(instance_agent(instance));
#endif
  v_shadow = sun_coords(v_world);
  gl_Position = u_view_proj * vec4(v_world, 1.0);
}
