/* Where a world point falls in the sun's shadow map (crowd_addon/gpu/shadows.py):
 * `shadow_view_tex` holds the sun's view-projection matrix (4 RGBA32F texels, its
 * columns). Worked out per vertex and interpolated: the sun's view is orthographic,
 * so the map coordinates of a triangle's points are its corners' interpolated
 * exactly, and a fragment reads no matrix (shading.glsl's sun_visibility). */

vec3 sun_coords(vec3 world)
{
#if SHADOWS
  mat4 m = mat4(texelFetch(shadow_view_tex, ivec2(0, 0), 0),
                texelFetch(shadow_view_tex, ivec2(1, 0), 0),
                texelFetch(shadow_view_tex, ivec2(2, 0), 0),
                texelFetch(shadow_view_tex, ivec2(3, 0), 0));
  vec4 c = m * vec4(world, 1.0);
  return c.xyz / c.w * 0.5 + 0.5;
#else
  return vec3(0.0);
#endif
}
