/* Lit shading of the crowd and its scene, in the surface's colour:
 * u_light = (direction towards the light, ambient). Lambert from the light (the
 * scene's sun), dimmed where the shadow map says the sun is hidden, plus a soft
 * hemisphere ambient: surfaces facing the sky get the full ambient level, those
 * facing the ground a third of it, so undersides and backs read as shaded instead
 * of flat.
 *
 * Shadows (SHADOWS 1): `v_shadow` is where the fragment falls in the sun's shadow
 * map (sun_coords.glsl, per vertex) and `shadow_tex` the depth the sun sees there
 * (crowd_addon/gpu/shadows.py). SHADOWS 0 (no shadows, and the shadow map's own
 * pass) reads neither: the sun is never hidden.
 *
 * Colours are linear (Blender's material colours, the agents' tints); the lit colour
 * is linear light. ENCODE_SRGB 1 writes it sRGB-encoded, for an image of plain 8-bit
 * values (the renderers' own offscreen images: PNG frames, reads); ENCODE_SRGB 0
 * writes it linear, for a framebuffer that encodes on write, as the sRGB overlay
 * buffer of Blender's viewport does. Either way the display shows what Blender's
 * Standard view transform shows for the same light. */

const float SHADOW_BIAS = 0.0015;       /* in the map's 0..1 depth */

/* How much of the sun reaches a fragment at `p`: its shadow-map coordinates
 * (sun_coords.glsl, interpolated from the vertices). */
float sun_visibility(vec3 p)
{
#if SHADOWS
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
    diffuse *= sun_visibility(v_shadow);
  }
  float sky = mix(1.0 / 3.0, 1.0, 0.5 + 0.5 * n.z);
  vec3 lit = v_color * (u_light.w * sky + (1.0 - u_light.w) * diffuse);
#if ENCODE_SRGB
  lit = clamp(lit, 0.0, 1.0);
  lit = mix(lit * 12.92, 1.055 * pow(lit, vec3(1.0 / 2.4)) - 0.055,
            step(vec3(0.0031308), lit));
#endif
  frag_color = vec4(lit, 1.0);
}
