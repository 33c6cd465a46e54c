/* Local SQT poses on the GPU (docs/architecture.md, matching crowd_addon/core/pose.py:
 * scale and translation lerp, quaternion (w, x, y, z) nlerp on the shortest arc,
 * then normalised; an SQT's matrix is T @ R @ S.
 */

struct Sqt {
  vec3 scale;
  vec4 rotation; /* (w, x, y, z) */
  vec3 translation;
};

/* Bone `bone` of logical row `row` of the local-pose texture `local_tex`: the ten
 * SQT floats in three texels (sx, sy, sz, qw), (qx, qy, qz, tx), (ty, tz, 0, 0)
 * (crowd_addon/core/pose_storage.py, LOCAL_IDENTITY). */
Sqt fetch_local_pose(int row, int bone)
{
  vec4 a = texelFetch(local_tex, pose_texel(row, 3 * bone), 0);
  vec4 b = texelFetch(local_tex, pose_texel(row, 3 * bone + 1), 0);
  vec4 c = texelFetch(local_tex, pose_texel(row, 3 * bone + 2), 0);
  Sqt p;
  p.scale = a.xyz;
  p.rotation = vec4(a.w, b.xyz);
  p.translation = vec3(b.w, c.xy);
  return p;
}

/* core.pose.blend2: a + (b - a) * w, rotations towards -b when they point apart. */
Sqt blend_sqt(Sqt a, Sqt b, float w)
{
  Sqt r;
  r.scale = a.scale + (b.scale - a.scale) * w;
  vec4 qb = dot(a.rotation, b.rotation) < 0.0 ? -b.rotation : b.rotation;
  r.rotation = normalize(a.rotation + (qb - a.rotation) * w);
  r.translation = a.translation + (b.translation - a.translation) * w;
  return r;
}

/* The affine matrix T @ R @ S (column major, as GLSL stores it). */
mat4 sqt_matrix(Sqt p)
{
  float w = p.rotation.x, x = p.rotation.y, y = p.rotation.z, z = p.rotation.w;
  float xx = x * x, yy = y * y, zz = z * z;
  float xy = x * y, xz = x * z, yz = y * z, wx = w * x, wy = w * y, wz = w * z;
  return mat4(vec4(1.0 - 2.0 * (yy + zz), 2.0 * (xy + wz), 2.0 * (xz - wy), 0.0) * p.scale.x,
              vec4(2.0 * (xy - wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz + wx), 0.0) * p.scale.y,
              vec4(2.0 * (xz + wy), 2.0 * (yz - wx), 1.0 - 2.0 * (xx + yy), 0.0) * p.scale.z,
              vec4(p.translation, 1.0));
}
