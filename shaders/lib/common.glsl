/* Helpers every pass shares (fragment stage; after constants.glsl): a closed mesh's inner
 * side, the tangent frame of a normal, the view and its bending above the horizon, the
 * per-pixel turn of a sample set, a texel of the row-wrapped data textures. */

/* core.scene.mesh.closed_side: 0 open, +1/-1 a closed mesh whose front faces look
 * outward/inward.  Its inner side sees only itself: no direct light, black as in Cycles. */
bool inner_side(float side)
{
  return side > 0.5 ? !gl_FrontFacing : (side < -0.5 ? gl_FrontFacing : false);
}

/* side 2: a two-sided mesh (core.scene.mesh.with_back_sides), whose sides are triangles of
 * their own: each is drawn from its front only, the copy seen from behind is discarded */
bool other_copy(float side)
{
  return side > 1.5 && !gl_FrontFacing;
}

/* Duff et al. 2017: tangent and bitangent completing a unit normal
 * (core.sphere.directions.orthonormal_frame) */
void tangent_frame(vec3 n, out vec3 tx, out vec3 ty)
{
  float sgn = n.z >= 0.0 ? 1.0 : -1.0;
  float q = -1.0 / (sgn + n.z);
  float r = n.x * n.y * q;
  tx = vec3(1.0 + sgn * n.x * n.x * q, sgn * r, -sgn * n.x);
  ty = vec3(r, sgn + n.y * n.y * q, -n.y);
}

/* the unit direction toward the viewer from p: eye = (position, 1) or (direction, 0) */
vec3 view_direction(vec4 eye, vec3 p)
{
  return eye.w > 0.5 ? normalize(eye.xyz - p) : normalize(eye.xyz);
}

/* a view with n.o below COS_VIEW_MIN raised to about it, keeping its azimuth
 * (core.shading.brdf._bend_views) */
vec3 bent_view(vec3 n, vec3 o)
{
  float c = dot(n, o);
  return c < COS_VIEW_MIN ? normalize(o + (COS_VIEW_MIN - c) * n) : o;
}

/* a pixel's turn of a sample set (Cranley-Patterson rotation), stepped along the R2
 * sequence from pixel to pixel: neighbouring pixels and F12's supersamples see other
 * samples, so a pattern averages out as noise */
vec2 pixel_shift()
{
  return fract(vec2(0.7548776662, 0.5698402910) * dot(floor(gl_FragCoord.xy), vec2(1.0, 61.0)));
}

/* texel i of a data texture whose texels run on across rows of ROW_TEXELS */
ivec2 row_texel(int i)
{
  return ivec2(i % ROW_TEXELS, i / ROW_TEXELS);
}
