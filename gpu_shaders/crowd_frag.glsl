/* Lit shading of the crowd and its scene, in the surface's colour:
 * u_light = (direction towards the light, ambient). Lambert from the light (the
 * scene's sun), dimmed where the shadow map says the sun is hidden, plus a soft
 * hemisphere ambient: surfaces facing the sky get the full ambient level, those
 * facing the ground a third of it, so undersides and backs read as shaded instead
 * of flat.
 *
 * Shadows (SHADOWS 1): `shadow_view_tex` holds the sun's view-projection matrix (4
 * RGBA32F texels, its columns) and `shadow_tex` the depth the sun sees through it
 * (crowd_addon/gpu/shadows.py). SHADOWS 0 (no shadows, and the shadow map's own
 * pass) reads neither: the sun is never hidden. */

const float SHADOW_BIAS = 0.0015;       /* in the map's 0..1 depth */

float sun_visibility(vec3 world)
{
#if SHADOWS
  mat4 m = mat4(texelFetch(shadow_view_tex, ivec2(0, 0), 0),
                texelFetch(shadow_view_tex, ivec2(1, 0), 0),
                texelFetch(shadow_view_tex, ivec2(2, 0), 0),
                texelFetch(shadow_view_tex, ivec2(3, 0), 0));
  vec4 c = m * vec4(world, 1.0);
  vec3 p = c.xyz / c.w * 0.5 + 0.5;
  if (any(lessThan(p, vec3(0.0))) || any(greaterThan(p, vec3(1.0)))) {
    return 1.0;
  }
  vec2 texel = 1.0 / vec2(textureSize(shadow_tex, 0));
  float lit = 0.0;
  for (int i = 0; i < 4; i++) {                   /* 2 x 2 samples: softer edges */
    vec2 at = p.xy + (vec2(i & 1, i >> 1) - 0.5) * texel;
    lit += (p.z - SHADOW_BIAS <= texture(shadow_tex, at).r) ? 1.0 : 0.0;
  }
  return lit * 0.25;
#else
  return 1.0;
#endif
}

void main()
{
  vec3 n = normalize(v_normal);
  if (!gl_FrontFacing) {
    n = -n;
  }
  float diffuse = max(dot(n, normalize(u_light.xyz)), 0.0);
  if (diffuse > 0.0) {
    diffuse *= sun_visibility(v_world);
  }
  float sky = mix(1.0 / 3.0, 1.0, 0.5 + 0.5 * n.z);
  frag_color = vec4(v_color * (u_light.w * sky + (1.0 - u_light.w) * diffuse), 1.0);
}
