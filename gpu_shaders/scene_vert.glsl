/* The scene around the crowd (stands, pitch, walls): world-space triangles with a
 * normal and a colour per corner, drawn through the same camera and lit by the same
 * fragment stage (crowd_frag.glsl) as the agents, so both share one light and one
 * depth buffer: an agent behind a wall is hidden by the depth test. */

void main()
{
  v_world = pos;
  v_shadow = sun_coords(pos);
  v_normal = nor;
  v_color = col;
  gl_Position = u_view_proj * vec4(pos, 1.0);
}
