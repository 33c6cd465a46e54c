/* Simple lit shading: Lambert from one directional light plus ambient, in the
 * agent's colour (u_light = (direction towards the light, ambient)). */

void main()
{
  vec3 n = normalize(v_normal);
  if (!gl_FrontFacing) {
    n = -n;
  }
  float diffuse = max(dot(n, normalize(u_light.xyz)), 0.0);
  frag_color = vec4(v_color * (u_light.w + (1.0 - u_light.w) * diffuse), 1.0);
}
