/* Lit shading of the crowd and its scene, in the surface's colour:
 * u_light = (direction towards the light, ambient). Lambert from the light (the
 * scene's sun) plus a soft hemisphere ambient: surfaces facing the sky get the full
 * ambient level, those facing the ground a third of it, so undersides and backs read
 * as shaded instead of flat. */

void main()
{
  vec3 n = normalize(v_normal);
  if (!gl_FrontFacing) {
    n = -n;
  }
  float diffuse = max(dot(n, normalize(u_light.xyz)), 0.0);
  float sky = mix(1.0 / 3.0, 1.0, 0.5 + 0.5 * n.z);
  frag_color = vec4(v_color * (u_light.w * sky + (1.0 - u_light.w) * diffuse), 1.0);
}
