/* Vertex capture for read-back without transform feedback (the Blender backend):
 * the crowd vertex (crowd_vertex.glsl, as crowd_vert.glsl draws it) of one agent
 * per instance, drawn as a point on pixel (gl_VertexID, gl_InstanceID) of an
 * RGBA32F target of u_capture_size pixels, where capture_frag.glsl writes v_world.
 * u_draw = (list base, agents, unused, unused).
 * Needs crowd_vertex.glsl and its libraries before it.
 */

void main()
{
  crowd_vertex(instance_agent(gl_InstanceID));
  v_shadow = vec3(0.0);
  vec2 pixel = vec2(gl_VertexID, gl_InstanceID) + 0.5;
  gl_Position = vec4(pixel / vec2(u_capture_size) * 2.0 - 1.0, 0.0, 1.0);
}
