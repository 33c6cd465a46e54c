/* Vertex capture: the skinned world position as the pixel's value. */

void main()
{
  frag_color = vec4(v_world, 1.0);
}
