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

/* (floor(i / n), i - n floor(i / n)) for n > 0 and |i| below 2^24: a float division and one
 * exact correction (the quotient lies at least 0.5 / n inside its step), where an integer
 * division by a value the compiler does not know is a scalar division per lane on a
 * software rasterizer */
ivec2 floor_div(int i, int n)
{
  int q = int(floor((float(i) + 0.5) / float(n)));
  int r = i - q * n;
  if (r < 0) {
    q -= 1;
    r += n;
  }
  else if (r >= n) {
    q += 1;
    r -= n;
  }
  return ivec2(q, r);
}

/* texel i of a data texture whose texels run on across rows of ROW_TEXELS */
ivec2 row_texel(int i)
{
  return ivec2(i % ROW_TEXELS, i / ROW_TEXELS);
}

/* the mirror's turn per sample (radians) past which its first-order prediction of where a
 * highlight falls between samples is not trusted: over a crease the normal bends across a
 * few triangles and the highlight is sampled (measured: a glossy Suzanne's brow lost 13 % of
 * a highlight's energy at any turn, a sphere's 48^2 highlights need up to 0.2) */
#define THROUGH_TURN_MAX 0.2

/* a highlight's spread (radians^2 per axis): the lobe's 2 alpha^2 and a disc's r^2 / 4 */
float highlight_spread2(float a, float r)
{
  return 2.0 * a * a + 0.25 * r * r;
}

/* the footprint's shorter side^2 (dx, dy: the mirror's change to the next sample): a
 * highlight of a smaller spread is drawn through the footprint (lights_frag.glsl
 * footprint_share); 0 for a mapped normal (its mirror turns with the map's texels, not
 * linearly) or a footprint turning past THROUGH_TURN_MAX; the lights and sharp passes
 * decide by this same rule */
float through_reach2(vec3 dx, vec3 dy, bool mapped)
{
  float xx = dot(dx, dx), yy = dot(dy, dy);
  return mapped || max(xx, yy) > THROUGH_TURN_MAX * THROUGH_TURN_MAX ? 0.0 : min(xx, yy);
}
