/* Compact light sources per pixel (addon/gpu/lights.py): the environment's extracted sources
 * (core/sphere/sources.py) and Blender's sun lamps, each a disc of uniform radiance seen from
 * every point in the same direction, added to the frame.
 *
 *   L_o = sum_sources V(x) * integral over the disc of  f(i, o) max(0, n.i) L  di
 *
 * Lambert: the disc's cosine integral is exact while it is above the horizon
 * (pi sin^2 r (n.c)), sampled otherwise.  Glossy lobes: multiple importance sampling with
 * the balance heuristic (Veach 1997) of NL points on the disc and NB samples of the NDF
 * that hit it, so a lobe narrower than a softbox and a lobe wider than the sun are both
 * integrated.  V: the source's shadow map, filtered to the disc's angular size (PCSS,
 * Fernando 2005: blocker search, penumbra = (receiver - blocker depth) * 2 tan r).
 * Light below the triangle's own plane does not reach the point (Cycles' shadow ray would
 * enter the surface), whatever the interpolated normal says.  A normal or bump map: as in
 * Cycles' Principled BSDF the glossy lobes take the mapped normal after the bump map
 * correction, the diffuse term the mapped normal as is, times the terminator factor.
 *
 * paramTex (one material slot), row 0: 0 (albedo / pi, has diffuse), 1 (alpha,
 * distribution 0 Beckmann / 1 GGX, lobe count, glossy drawn here), 2.. per lobe (kind,
 * weight, eta, -), (f0, -), (B, -) (core.shading.brdf.sharp_lobes), 8 eye (w = 1 perspective),
 * 9 (core.scene.mesh.closed_side of the object, 1 when the sharp pass draws the slot's
 * lobes, -, -), 11 (roughness nodes n, alpha floor),
 * 12-15 a textured Roughness (texture.glsl's info, mapping rows, mix colour);
 * 16 a normal or bump map (kind 0 none / 1 Normal Map / 2 Bump, strength, distance, -),
 * 17-20 its image (info, mapping rows, mix colour: texture.glsl mapped_normal), 21-23 an
 * instance's normal matrix over its source's shared batch (PLACED: lights_vert.glsl);
 * row 1: the Lambert base's view weight at mu = i / (TABLE_NODES - 1) (Principled layering),
 * rows 2, 3: each lobe's multiscatter factor at mu (core.shading.brdf.multiscatter_factor);
 * with a textured Roughness rows 4k + 4 .. 4k + 7 the same four rows at roughness node
 * k / (n - 1), interpolated at the pixel's roughness (addon/gpu/lights.py slot_texels).
 * srcTex, row s per source: 0 (direction toward it, angular radius), 1 (radiance, kind:
 * 0 a disc, 1 point-like (radiance is then its irradiance)), 2..5 world-to-shadow-clip
 * columns, 6 (atlas tile origin x, y and size in texels, depth range in world units),
 * 7 (shadow texel size in world units, the map's x axis in world space), 8 (1 for a
 * compact source of the World's image, 0 for a sun lamp, -, -, -); tile size 0:
 * no shadow map (past the atlas's budget, addon/frame/sources.py shadow_plan).  A local lamp:
 * 0 (position, sphere radius), 1 (power times colour, kind 2 point / 3 spot), 2 (spot
 * axis, cos of its half angle), 3 (spot smoothstep width), 6 (-, -, cubeTex face size; 0:
 * no shadow map), 8..31 the six faces' world-to-clip columns, 32..34 the faces' tile
 * origins in cubeTex (x, y of faces 2k and 2k + 1; x < 0 a face not drawn).  Every
 * source is drawn (no cap): the rows hold the distant sources, then the point and spot
 * lamps, then the area lamps, and row 0's COUNT_TEXEL how many of each (main loops over
 * each group with its own code, light_term).  An area lamp (kind 4 a
 * rectangle, 5 an ellipse): 0 (centre, radius of a disc of its area), 1 (radiance), 2 (the
 * way it faces), 4, 5 (its half axes), and its cube shadow map as a local lamp's.
 *
 * Features are compiled in only where a draw has them (addon/gpu/lights.py _shader: GLOSSY,
 * ROUGH_TEX, NORMAL_MAP, ALBEDO_TEX per slot, LOCAL_LAMPS, AREA_LAMPS, LIGHT_TILES (many
 * lights: a list per screen tile, tileTex) per frame): a branch
 * no fragment takes still costs registers on a GPU and its whole body on llvmpipe, which
 * runs both sides of a branch under a mask. */

/* glossy samples per source and sample: LOBE_TAPS (LOBE_SAMPLES) on the disc and as many of the
 * NDF, an area lamp's AREA_GRID^2 points on it; fewer per sample when each pixel has several
 * (addon/gpu/lights.py frame_features), which turn their patterns differently */
#ifndef LOBE_TAPS
#define LOBE_TAPS LOBE_SAMPLES
#endif
#define NL LOBE_TAPS
#define NB LOBE_TAPS
#define AREA_GRID (LOBE_TAPS >= 8 ? 4 : 2)
/* a source whose angular radius is below SMALL_SOURCE times the lobe's alpha (the reflected
 * lobe's angular spread) lights the lobe as a point of its solid angle: the lobe's relative
 * change over the disc is at most (r / alpha)^2 / 4 at its peak, 1 % here */
#define SMALL_SOURCE 0.2
/* the footprint kernel's least spread, in samples: the sample's box softened by a box's
 * variance (1/12), about a tent, so the samples interpolate a highlight linearly */
#define FOOTPRINT_SOFT 0.28867513
/* shadow-map filter taps per source and sample: FILTER_TAPS (addon/gpu/lights.py), or fewer
 * when each pixel has several samples; the blocker search takes BLOCKER_TAPS */
#ifndef PCF_TAPS
#define PCF_TAPS FILTER_TAPS
#endif

/* the roughness nodes the pixel lies between (nodeCount 1: the slot's own rows) */
int nodeCount = 1, nodeRow0 = 0, nodeRow1 = 0;
float nodeFrac = 0.0;

vec4 param(int i, int row)
{
#ifdef ROUGH_TEX
  if (nodeCount >= 2) {
    return mix(texelFetch(paramTex, ivec2(i, row + nodeRow0), 0),
               texelFetch(paramTex, ivec2(i, row + nodeRow1), 0), nodeFrac);
  }
#endif
  return texelFetch(paramTex, ivec2(i, row), 0);
}

/* a textured Roughness: select the nodes and return alpha (else -1) */
float textured_alpha()
{
#ifndef ROUGH_TEX
  return -1.0;
#else
  vec4 t = texelFetch(paramTex, ivec2(11, 0), 0);
  int n = int(t.x + 0.5);
  if (n < 2) {
    return -1.0;
  }
  vec4 info = texelFetch(paramTex, ivec2(12, 0), 0);
  vec3 c = input_colour(roughTex, vUv, vAttr, info, texelFetch(paramTex, ivec2(13, 0), 0).xyz,
                        texelFetch(paramTex, ivec2(14, 0), 0).xyz,
                        texelFetch(paramTex, ivec2(15, 0), 0));
  float r = scalar_input(c);
  float x = r * float(n - 1);
  int k = min(int(x), n - 2);
  nodeCount = n;
  nodeRow0 = 4 + 4 * k;
  nodeRow1 = 8 + 4 * k;
  nodeFrac = x - float(k);
  return max(r * r, t.y);
#endif
}

vec4 source(int s, int i)
{
  return texelFetch(srcTex, ivec2(i, s), 0);
}

vec3 table(int row, float mu)
{
  float x = clamp(mu, 0.0, 1.0) * float(TABLE_NODES - 1);
  int i0 = min(int(x), TABLE_NODES - 2);
  return mix(param(i0, row).rgb, param(i0 + 1, row).rgb, x - float(i0));
}

/* a mapped normal: the smooth one (Cycles' sd->N); light below its horizon reaches no
 * closure (texture.glsl bump_shadowing's side rule) */
bool mappedN = false;
vec3 smoothN = vec3(0.0, 0.0, 1.0);

/* the slot's glossy lobes (paramTex rows 2 + 3 j .. 4 + 3 j: kind, weight, eta; f0; B), read
 * once per fragment (read_lobes), not per sample of every light */
vec4 lobeKind0 = vec4(0.0), lobeKind1 = vec4(0.0);
vec3 lobeF00 = vec3(0.0), lobeF01 = vec3(0.0), lobeB0 = vec3(0.0), lobeB1 = vec3(0.0);

void read_lobes(int lobes)
{
  if (lobes > 0) {
    lobeKind0 = param(2, 0);
    lobeF00 = param(3, 0).rgb;
    lobeB0 = param(4, 0).rgb;
  }
  if (lobes > 1) {
    lobeKind1 = param(5, 0);
    lobeF01 = param(6, 0).rgb;
    lobeB1 = param(7, 0).rgb;
  }
}

/* glossy lobes' f * cos (Fresnel, NDF, masking, multiscatter), at unit i */
vec3 glossy_f_cos(vec3 n, vec3 o, vec3 i, float cos_o, float a, int dist, int lobes,
                  float lam_o, vec3 ms0, vec3 ms1)
{
  float cos_i = dot(n, i);
  vec3 hv = o + i;
  float len2 = dot(hv, hv);
  if (cos_i <= 0.0 || len2 < 1e-20 || (mappedN && dot(smoothN, i) * dot(smoothN, n) < 0.0)) {
    return vec3(0.0);
  }
  vec3 h = hv * inversesqrt(len2);
  float common_term = ndf(dist, a, dot(n, h)) /
                      (4.0 * cos_o * (1.0 + smith_lambda(dist, a, cos_i) + lam_o));
  float oh = clamp(dot(o, h), 0.0, 1.0);
  vec3 f = vec3(0.0);
  if (lobes > 0) {
    f += lobeKind0.y * ms0 * lobe_fresnel(SIG_KIND0(int(lobeKind0.x + 0.5)), lobeF00, lobeB0,
                                          lobeKind0.z, oh);
  }
  if (lobes > 1) {
    f += lobeKind1.y * ms1 * lobe_fresnel(SIG_KIND1(int(lobeKind1.x + 0.5)), lobeF01, lobeB1,
                                          lobeKind1.z, oh);
  }
  return f * common_term;
}

/* the sample's mirror direction, position and their change to the next sample in x and y
 * (ray differentials: Cycles integrates the pixel over them) */
vec3 mirror, mdx, mdy, pdx, pdy;

/* erf (Abramowitz and Stegun 7.1.26-like, |error| < 2e-4) */
float erf_approx(float x)
{
  float x2 = x * x;
  return sign(x) * sqrt(1.0 - exp(-x2 * (1.2732395 + 0.147 * x2) / (1.0 + 0.147 * x2)));
}

/* the part of a Gaussian of spread s (samples) centred d samples away that falls in this
 * sample's box: summed over the grid of samples it is 1 for any d (partition of unity) */
float box_gauss(float d, float s)
{
  float k = 0.70710678 / s;
  return 0.5 * (erf_approx((d + 0.5) * k) - erf_approx((d - 0.5) * k));
}

/* a highlight narrower than the samples: the mirror reaches the source's direction c at
 * d = J^+ (c - mirror) samples from here (J = [ex ey], the change of mirror - c per sample:
 * a local lamp's direction turns by (I - c c^T) dP / distance, inv_dist 0 for a distant
 * one), where the image holds the lobe's energy over |J|^-1 of screen (per unit of
 * f cos L omega); each sample takes the share of it that a Gaussian of the lobe's and
 * disc's variance sr2 (radians^2 per axis, mapped to the screen by J^+) puts in its box,
 * so the frame holds the highlight's energy whatever the samples' grid, where sampling the
 * lobe at points would alias */
float footprint_share(vec3 c, float sr2, float inv_dist)
{
  vec3 ex = mdx + (pdx - c * dot(c, pdx)) * inv_dist;
  vec3 ey = mdy + (pdy - c * dot(c, pdy)) * inv_dist;
  float gxx = dot(ex, ex), gyy = dot(ey, ey), gxy = dot(ex, ey);
  float gdet = gxx * gyy - gxy * gxy;
  if (gdet < 1e-24) {
    return 0.0;
  }
  /* c in the mirror's tangent plane (gnomonic): a direction far from the mirror stays far
   * (c - mirror's tangent part alone would bring one near -mirror back to d ~ 0) */
  float cm = dot(c, mirror);
  if (cm <= 0.0) {
    return 0.0;
  }
  vec3 d = c / cm - mirror;
  float bx = dot(ex, d), by = dot(ey, d);
  float ox = (gyy * bx - gxy * by) / gdet, oy = (gxx * by - gxy * bx) / gdet;
  float sx = sqrt(sr2 * gyy / gdet + FOOTPRINT_SOFT * FOOTPRINT_SOFT);
  float sy = sqrt(sr2 * gxx / gdet + FOOTPRINT_SOFT * FOOTPRINT_SOFT);
  return box_gauss(ox, sx) * box_gauss(oy, sy) * inversesqrt(gdet);
}

/* pdf of the NDF sampling of sample_ndf mapped to directions: D (n.h) / (4 o.h) */
float ndf_pdf(vec3 n, vec3 o, vec3 i, float a, int dist)
{
  vec3 h = normalize(o + i);
  float oh = dot(o, h);
  return oh > 0.0 ? ndf(dist, a, max(dot(n, h), 0.0)) * max(dot(n, h), 0.0) / (4.0 * oh) : 0.0;
}

/* a direction in the cone of half angle r about c, uniform in solid angle */
vec3 cone_sample(vec3 c, float cos_r, vec2 u)
{
  vec3 tx, ty;
  tangent_frame(c, tx, ty);
  float ct = 1.0 - u.x * (1.0 - cos_r);
  float st = sqrt(max(1.0 - ct * ct, 0.0));
  float phi = 2.0 * PI * u.y;
  return tx * (st * cos(phi)) + ty * (st * sin(phi)) + c * ct;
}

/* the direction of NDF sample b (sample_ndf's half vector mirrored about it), turned
 * per pixel by shift; false when the half vector faces away from o */
bool ndf_direction(int b, vec3 n, vec3 o, float a, int dist, vec3 tx, vec3 ty, vec2 shift,
                   out vec3 i)
{
  vec2 u = fract(vec2((float(b) + 0.5) / float(NB), radical_inverse(b + 7)) + shift.yx);
  vec3 h = sample_ndf(dist, a, u, n, tx, ty);
  float oh = dot(o, h);
  i = 2.0 * oh * h - o;
  return oh > 0.0;
}

/* ---------------------------------------------------------------- shadow maps */

/* taps on a disc: k of n on a Vogel (golden-angle) spiral, even in area for any n; `dir`
 * starts at the pixel's rotation and turns by the golden angle per tap (step_tap) */
const vec2 GOLDEN = vec2(-0.7373688, 0.6754903);

vec2 disc_tap(int k, int n, vec2 dir)
{
  return dir * sqrt((float(k) + 0.5) / float(n));
}

vec2 step_tap(vec2 dir)
{
  return vec2(dir.x * GOLDEN.x - dir.y * GOLDEN.y, dir.x * GOLDEN.y + dir.y * GOLDEN.x);
}

/* taps for a disc of `radius` texels: about one per texel it covers, 4 to `most` */
int tap_count(float radius, int most)
{
  return clamp(int(ceil(PI * radius * radius)), 4, most);
}

/* depth at uv in [0, 1]^2 of a tile (origin x, y and size in texels of the atlas) */
float shadow_depth(vec4 tile, vec2 uv)
{
  ivec2 px = ivec2(tile.xy + clamp(uv, 0.0, 1.0) * tile.z);
  px = clamp(px, ivec2(tile.xy), ivec2(tile.xy) + int(tile.z) - 1);
  return texelFetch(shadowTex, px, 0).r;
}

float visibility(int s, vec3 p, vec3 ng, float radius, vec2 shift)
{
  vec4 tile = source(s, 6);
  vec4 s7 = source(s, 7);
  float texel = s7.x;
  if (tile.z <= 0.0) {
    return 1.0;
  }
  vec3 toward = source(s, 0).xyz;
  vec3 ax = s7.yzw;                                    /* the map's x axis; y = toward x ax */
  vec3 ay = cross(toward, ax);
  float cos_l = max(dot(ng, toward), 0.1);
  /* a little normal offset and bias against acne, no more (light would leak at contact) */
  vec3 q = p + ng * (1.5 * texel);
  vec4 lc = mat4(source(s, 2), source(s, 3), source(s, 4), source(s, 5)) * vec4(q, 1.0);
  vec3 ndc = lc.xyz / lc.w;
  vec2 uv = ndc.xy * 0.5 + 0.5;
  float z = ndc.z * 0.5 + 0.5;
  if (any(lessThan(uv, vec2(0.0))) || any(greaterThan(uv, vec2(1.0))) || z >= 1.0) {
    return 1.0;
  }
  float depth_range = tile.w;
  float bias = 2.0 * texel / depth_range;
  /* the receiver's plane in the map: its depth at an offset of the lookup (receiver-plane
   * depth bias), so a wide filter on a sloped surface does not shadow the surface itself */
  vec2 slope = vec2(dot(ng, ax), dot(ng, ay)) / cos_l;
  float spread = 2.0 * tan(radius);                    /* penumbra per unit of distance */
  /* blocker search over the largest penumbra a blocker up to the light could cast */
  float search = clamp(z * depth_range * spread / texel, 1.0, 48.0);
  vec2 turn = vec2(cos(2.0 * PI * shift.x), sin(2.0 * PI * shift.x));
  float blockers = 0.0, sum = 0.0;
  float uv_texel = 1.0 / tile.z;
  int nb = tap_count(search, BLOCKER_TAPS);
  vec2 dir = turn;
  for (int k = 0; k < nb; k++) {
    vec2 off = disc_tap(k, nb, dir) * search * uv_texel;
    dir = step_tap(dir);
    float d = shadow_depth(tile, uv + off);
    if (d < z + dot(off, slope) - bias) {
      blockers += 1.0;
      sum += d;
    }
  }
  if (blockers == 0.0) {
    return 1.0;
  }
  float penumbra = max(z - sum / blockers, 0.0) * depth_range * spread / texel;  /* texels */
  float filter_radius = max(0.5 * penumbra, 0.75);
  int nf = tap_count(filter_radius, PCF_TAPS);
  float lit = 0.0;
  dir = turn;
  for (int k = 0; k < nf; k++) {
    vec2 off = disc_tap(k, nf, dir) * filter_radius * uv_texel;
    dir = step_tap(dir);
    lit += shadow_depth(tile, uv + off) < z + dot(off, slope) - bias ? 0.0 : 1.0;
  }
  return lit / float(nf);
}

/* a local lamp's shadow: six 90-degree faces around it (+X, -X, +Y, -Y, +Z, -Z, matrices
 * in srcTex texels 8..31), each holding the distance to the lamp of what it sees; PCSS
 * with the lamp's radius: penumbra = (receiver - blocker) / blocker * 2 R */
float local_visibility(int s, vec3 p, vec3 ng, vec3 lamp, float lamp_radius, vec2 shift)
{
  vec4 tile = source(s, 6);
  if (tile.z <= 0.0) {
    return 1.0;
  }
  vec3 v0 = p - lamp;
  float texel = 2.0 * max(max(abs(v0.x), abs(v0.y)), abs(v0.z)) / tile.z;
  vec3 q = p + ng * (1.5 * texel);
  vec3 v = q - lamp;
  vec3 av = abs(v);
  int face = av.x >= av.y && av.x >= av.z ? (v.x >= 0.0 ? 0 : 1) :
             (av.y >= av.z ? (v.y >= 0.0 ? 2 : 3) : (v.z >= 0.0 ? 4 : 5));
  vec4 lc = mat4(source(s, 8 + 4 * face), source(s, 9 + 4 * face), source(s, 10 + 4 * face),
                 source(s, 11 + 4 * face)) * vec4(q, 1.0);
  vec2 uv = clamp(lc.xy / lc.w * 0.5 + 0.5, 0.0, 1.0);
  vec4 origins = source(s, 32 + face / 2);
  vec4 ftile = vec4(face % 2 == 0 ? origins.xy : origins.zw, tile.z, 0.0);
  if (ftile.x < 0.0) {
    return 1.0;             /* a face the lamp does not light through (a spot's, an area's) */
  }
  float d = length(v);
  float bias = 2.0 * texel;
  /* receiver-plane bias: a tap `k` texels off reads the receiver's own plane up to
   * k texel tan(incidence) nearer the lamp (grazing receivers must not shadow themselves) */
  float cos_l = max(dot(ng, -v / max(length(v), 1e-12)), 0.1);
  float slope = texel * sqrt(1.0 - cos_l * cos_l) / cos_l;
  vec2 turn = vec2(cos(2.0 * PI * shift.x), sin(2.0 * PI * shift.x));
  float uv_texel = 1.0 / tile.z;
  float search = clamp(lamp_radius / texel, 1.0, 24.0);
  float blockers = 0.0, sum = 0.0;
  int nb = tap_count(search, BLOCKER_TAPS);
  vec2 dir = turn;
  for (int k = 0; k < nb; k++) {
    vec2 tap = disc_tap(k, nb, dir);
    dir = step_tap(dir);
    float b = texelFetch(cubeTex, ivec2(ftile.xy + clamp(uv + tap * search * uv_texel, 0.0, 1.0)
                                        * (tile.z - 1.0)), 0).r;
    if (b < d - bias - length(tap) * search * slope) {
      blockers += 1.0;
      sum += b;
    }
  }
  if (blockers == 0.0) {
    return 1.0;
  }
  float avg = max(sum / blockers, 1e-6);
  float penumbra = (d - avg) / avg * 2.0 * lamp_radius / texel;       /* in texels */
  float filter_radius = clamp(0.5 * penumbra, 0.75, 32.0);
  int nf = tap_count(filter_radius, PCF_TAPS);
  float lit = 0.0;
  dir = turn;
  for (int k = 0; k < nf; k++) {
    vec2 tap = disc_tap(k, nf, dir);
    dir = step_tap(dir);
    float b = texelFetch(cubeTex, ivec2(ftile.xy + clamp(uv + tap * filter_radius * uv_texel,
                                                         0.0, 1.0) * (tile.z - 1.0)), 0).r;
    lit += b < d - bias - length(tap) * filter_radius * slope ? 0.0 : 1.0;
  }
  return lit / float(nf);
}

/* ---------------------------------------------------------------- area lamps */

#define NA (AREA_GRID * AREA_GRID)

/* a point of an area lamp's shape for u in [0, 1)^2, uniform in area: the square as is,
 * the disc by the concentric map (Shirley and Chiu 1997) */
vec2 shape_point(vec2 u, bool ellipse)
{
  vec2 p = 2.0 * u - 1.0;
  if (!ellipse || (p.x == 0.0 && p.y == 0.0)) {
    return p;
  }
  float r, phi;
  if (abs(p.x) > abs(p.y)) {
    r = p.x;
    phi = 0.25 * PI * (p.y / p.x);
  }
  else {
    r = p.y;
    phi = 0.5 * PI - 0.25 * PI * (p.x / p.y);
  }
  return r * vec2(cos(phi), sin(phi));
}

#define POLY 16

/* vertex k of an area lamp's polygon: the rectangle's corners, or the regular 16-gon of the
 * ellipse's area (radius scale sqrt(pi / (8 sin(pi / 8)))) */
vec3 lamp_vertex(vec3 centre, vec3 hx, vec3 hy, bool ellipse, int k)
{
  float grow = 1.0129870;
  vec2 c = ellipse ? grow * vec2(cos(2.0 * PI * float(k) / float(POLY)),
                                 sin(2.0 * PI * float(k) / float(POLY)))
                   : vec2(k == 1 || k == 2 ? 1.0 : -1.0, k >= 2 ? 1.0 : -1.0);
  return centre + c.x * hx + c.y * hy;
}

/* one edge's term of Lambert's formula, unit vectors a to b about n */
float edge_term(vec3 n, vec3 a, vec3 b)
{
  vec3 c = cross(a, b);
  float l = length(c);
  return l > 1e-9 ? acos(clamp(dot(a, b), -1.0, 1.0)) * dot(n, c) / l : 0.0;
}

/* the next vertex v of a clipped polygon: its edge from the one before summed */
void clipped_vertex(vec3 n, vec3 v, inout bool started, inout vec3 first, inout vec3 prev,
                    inout float sum)
{
  if (started) {
    sum += edge_term(n, prev, v);
  }
  else {
    first = v;
    started = true;
  }
  prev = v;
}

/* integral of max(0, n.i) over the solid angle of an area lamp's polygon (convex, its
 * vertices in order) seen from p: the polygon clipped to p's horizon (Sutherland-Hodgman),
 * then Lambert's edge formula (1/2) sum acos(a.b) n.(a x b)/|a x b| -- exact.  The clipped
 * vertices are met in order as the edges are walked and each edge's term summed at once:
 * no array (a GPU keeps a dynamically indexed local array in memory, llvmpipe per lane) */
float polygon_cosine(vec3 p, vec3 n, vec3 centre, vec3 hx, vec3 hy, bool ellipse)
{
  int count = ellipse ? POLY : 4;
  vec3 a = lamp_vertex(centre, hx, hy, ellipse, 0) - p;
  float da = dot(a, n);
  vec3 first = vec3(0.0), prev = vec3(0.0);
  bool started = false;
  float sum = 0.0;
  for (int k = 0; k < count; k++) {
    vec3 b = lamp_vertex(centre, hx, hy, ellipse, k + 1 == count ? 0 : k + 1) - p;
    float db = dot(b, n);
    /* the clipped polygon's next vertices: a above the horizon, then where the edge
     * crosses it */
    if (da > 0.0) {
      clipped_vertex(n, normalize(a), started, first, prev, sum);
    }
    if ((da > 0.0) != (db > 0.0)) {
      clipped_vertex(n, normalize(a + (b - a) * (da / (da - db))), started, first, prev, sum);
    }
    a = b;
    da = db;
  }
  if (started) {
    sum += edge_term(n, prev, first);
  }
  return 0.5 * abs(sum);
}

/* an area lamp (srcTex row 0 centre, 1 radiance, 2 the way it faces, 4 and 5 its half
 * axes): the Lambert term exactly (polygon_cosine; an ellipse as the 16-gon of its area),
 * the glossy lobes by NA stratified points on it and NB samples of the NDF that hit its
 * front, combined by the balance heuristic */
vec3 area_lamp(int s, bool ellipse, vec3 n, vec3 nd, vec3 ng, vec3 o, float cos_o, vec4 kd, vec3 wd,
               float a, int dist, int lobes, bool glossy, float lam_o, vec3 ms0, vec3 ms1,
               vec3 tx, vec3 ty, vec2 shift)
{
  vec4 s0 = source(s, 0);
  vec3 centre = s0.xyz;
  vec3 L = source(s, 1).rgb;
  vec3 facing = source(s, 2).xyz;
  vec3 hx = source(s, 4).xyz, hy = source(s, 5).xyz;
  float area = 4.0 * length(cross(hx, hy)) * (ellipse ? 0.25 * PI : 1.0);
  vec2 jitter = fract(shift + vec2(0.5));
  vec3 sum = vec3(0.0);
  if (kd.w > 0.5) {
    /* a mapped normal's terminator factor at the lamp's centre */
    sum += kd.rgb * wd * polygon_cosine(vPos, nd, centre, hx, hy, ellipse) * L *
           (mappedN ? bump_shadowing(smoothN, nd, normalize(centre - vPos)) : 1.0);
  }
  if (!glossy) {
    return sum;
  }
  /* small against the lobe: a point of the lamp's solid angle at its centre */
  vec3 wc = centre - vPos;
  float dc2 = max(dot(wc, wc), 1e-12);
  vec3 ic = wc * inversesqrt(dc2);
  float cos_c = -dot(ic, facing);
  float rc = s0.w * inversesqrt(dc2);                /* angular radius of its area's disc */
  if (rc < SMALL_SOURCE * a && cos_c > rc && dot(ng, ic) > rc) {
    return sum + glossy_f_cos(n, o, ic, cos_o, a, dist, lobes, lam_o, ms0, ms1) * L *
                 (area * cos_c / dc2);
  }
  for (int l = 0; l < NA; l++) {
    vec2 p = shape_point((vec2(float(l % AREA_GRID), float(l / AREA_GRID)) + jitter) /
                         float(AREA_GRID), ellipse);
    vec3 w = centre + p.x * hx + p.y * hy - vPos;
    float d2 = max(dot(w, w), 1e-12);
    vec3 i = w * inversesqrt(d2);
    float cos_l = -dot(i, facing);
    if (cos_l <= 0.0 || dot(ng, i) <= 0.0) {
      continue;
    }
    float pl = d2 / (cos_l * area);                 /* solid-angle pdf of the point */
    sum += glossy_f_cos(n, o, i, cos_o, a, dist, lobes, lam_o, ms0, ms1) * L /
           (float(NA) * pl + float(NB) * ndf_pdf(n, o, i, a, dist));
  }
  for (int b = 0; b < NB; b++) {
    vec3 i;
    if (!ndf_direction(b, n, o, a, dist, tx, ty, shift, i)) {
      continue;
    }
    float denom = dot(i, facing);
    if (denom >= 0.0 || dot(ng, i) <= 0.0) {
      continue;
    }
    float t = dot(centre - vPos, facing) / denom;
    vec3 rel = vPos + t * i - centre;
    vec2 p = vec2(dot(rel, hx) / dot(hx, hx), dot(rel, hy) / dot(hy, hy));
    if (t <= 0.0 || (ellipse ? dot(p, p) > 1.0 : max(abs(p.x), abs(p.y)) > 1.0)) {
      continue;                                     /* misses the lamp */
    }
    float pl = t * t / (-denom * area);
    sum += glossy_f_cos(n, o, i, cos_o, a, dist, lobes, lam_o, ms0, ms1) * L /
           (float(NA) * pl + float(NB) * ndf_pdf(n, o, i, a, dist));
  }
  return sum;
}

/* ---------------------------------------------------------------- one light */

/* the light groups in srcTex's order (addon/gpu/lights.py draws): distant sources, point and
 * spot lamps, area lamps.  main passes the group as a literal, so each loop compiles its own
 * kind's code only (llvmpipe would run every kind's under a mask, a GPU keeps its registers) */
#define DISTANT_GROUP 0
#define LOCAL_GROUP 1
#define AREA_GROUP 2

/* light s's share of the fragment's radiance (main's shading state passed in) */
vec3 light_term(int group, int s, vec3 n, vec3 nd, vec3 ng, vec3 o, float cos_o, vec4 kd,
                vec3 wd, float a, float a0, int dist, int lobes, bool glossy, bool sharpSlot,
                bool mapped, float lam_o, vec3 ms0, vec3 ms1, float reach2, vec3 spec_w,
                vec3 tx, vec3 ty, vec2 shift)
{
  vec4 s0 = source(s, 0);
  vec4 s1 = source(s, 1);
  vec3 c = s0.xyz;
  float r = s0.w;
  float kind = s1.w;      /* 0 disc, 1 point-like direction, 2 point, 3 spot, 4/5 area */
  float inv_dist = 0.0;   /* a local lamp: 1 / its distance (footprint_share) */
  /* the highlight's spread per axis (lobe 2 alpha^2, disc r^2 / 4; a point-like or
   * local source's none): narrower than the samples, it is drawn through the footprint */
  float sr2 = highlight_spread2(a0, kind > 0.5 ? 0.0 : r);
  /* a slot whose lobes the sharp pass draws reflects a compact source of the World here
   * only where it is drawn through the footprint (the sharp pass leaves its pixels out
   * there, sharp_lobe_frag.glsl; elsewhere it reads them, the source's true shape) */
  bool glossyHere = glossy && (!sharpSlot || kind > 1.5 || source(s, 8).x < 0.5 ||
                               sr2 < reach2);
#ifdef AREA_LAMPS
  if (group == AREA_GROUP) {        /* an area lamp: a rectangle (4) or an ellipse (5) */
    if (dot(vPos - s0.xyz, source(s, 2).xyz) <= 0.0) {
      return vec3(0.0);                           /* behind its emitting side */
    }
    /* the whole lamp below the shading normals' horizons adds nothing: no shadow taps
     * (its corners, an ellipse's 16-gon reaching 1.013 of its half axes) */
    vec3 w0 = s0.xyz - vPos, hx = 1.02 * source(s, 4).xyz, hy = 1.02 * source(s, 5).xyz;
    if ((kd.w < 0.5 || dot(nd, w0) + abs(dot(nd, hx)) + abs(dot(nd, hy)) <= 0.0) &&
        (!glossyHere || dot(n, w0) + abs(dot(n, hx)) + abs(dot(n, hy)) <= 0.0)) {
      return vec3(0.0);
    }
    float Va = local_visibility(s, vPos, ng, s0.xyz, s0.w, shift);
    return Va > 0.0 ? Va * area_lamp(s, kind > 4.5, n, nd, ng, o, cos_o, kd, wd, a, dist,
                                     lobes, glossyHere, lam_o, ms0, ms1, tx, ty, shift)
                    : vec3(0.0);
  }
#endif
#ifdef LOCAL_LAMPS
  if (group == LOCAL_GROUP) {       /* a local lamp: the sphere seen from here */
    vec3 to_lamp = s0.xyz - vPos;
    float d2 = max(dot(to_lamp, to_lamp), 1e-12);
    inv_dist = inversesqrt(d2);
    c = to_lamp * inversesqrt(d2);
    float e = 1.0 / (4.0 * PI * d2);              /* Cycles: Phi / (4 pi d^2) at normal */
    if (kind > 2.5) {                             /* spot cone (core.sg.lighting) */
      vec4 spot = source(s, 2);
      float smooth_w = source(s, 3).x;
      float t = dot(-c, spot.xyz);
      e *= smooth_w > 0.0 ? smoothstep(0.0, 1.0, (t - spot.w) / smooth_w)
                          : (t > spot.w ? 1.0 : 0.0);
    }
    if (e <= 0.0) {
      return vec3(0.0);
    }
    r = asin(min(s0.w * inversesqrt(d2), 0.999));
    kind = r < 1e-4 ? 1.0 : 0.0;
    s1.rgb *= kind > 0.5 ? e : e / (PI * sin(r) * sin(r));
  }
#endif
  float below = -sin(r);
  if (dot(ng, c) < below) {
    return vec3(0.0);                             /* the whole disc is below the plane */
  }
  /* or below the shading normals' horizons (the diffuse term's, the glossy lobes'): it adds
   * nothing there, and its shadow taps are the pass's largest cost */
  if ((kd.w < 0.5 || dot(nd, c) < below) && (!glossyHere || dot(n, c) < below)) {
    return vec3(0.0);
  }
  float V = group == LOCAL_GROUP ? local_visibility(s, vPos, ng, s0.xyz, s0.w, shift)
                                 : visibility(s, vPos, ng, r, shift);
  if (V <= 0.0) {
    return vec3(0.0);
  }
  vec3 sum = vec3(0.0);
  bool through = glossyHere && sr2 < reach2;
  vec3 glossy_through = through && dot(n, c) > 0.0 &&
                        !(mappedN && dot(smoothN, c) * dot(smoothN, n) < 0.0)
                        ? spec_w * footprint_share(c, sr2, inv_dist) : vec3(0.0);
  if (kind > 0.5) {                               /* point-like: its irradiance */
    if (dot(ng, c) > 0.0) {
      sum = (kd.rgb * wd * max(dot(nd, c), 0.0) * (mapped ? bump_shadowing(smoothN, nd, c) : 1.0) +
             (through ? glossy_through :
              glossyHere ? glossy_f_cos(n, o, c, cos_o, a, dist, lobes, lam_o, ms0, ms1)
                     : vec3(0.0))) * s1.rgb;
    }
  }
  else {
    float cos_r = cos(r);
    float omega = 2.0 * PI * (1.0 - cos_r);
    vec3 L = s1.rgb;
    /* Lambert: the cap's exact cosine integral while above both horizons */
    float nc = dot(nd, c);
    float sr = sin(r);
    bool clear = nc >= sr && dot(ng, c) >= sr;
    if (kd.w > 0.5 && clear) {
      /* a mapped normal's terminator factor at the disc's centre */
      sum += kd.rgb * wd * (PI * sr * sr * nc) * L *
             (mapped ? bump_shadowing(smoothN, nd, c) : 1.0);
    }
    /* a disc small against the lobe and clear of both horizons: the lobe at its centre */
    bool lobeSampled = glossyHere && !through && !(clear && r < SMALL_SOURCE * a);
    if (through) {
      sum += glossy_through * (omega * L);
    }
    else if (glossyHere && !lobeSampled) {
      sum += glossy_f_cos(n, o, c, cos_o, a, dist, lobes, lam_o, ms0, ms1) * (omega * L);
    }
    for (int l = 0; l < (lobeSampled || (kd.w > 0.5 && !clear) ? NL : 0); l++) {
      vec2 u = fract(vec2((float(l) + 0.5) / float(NL), radical_inverse(l)) + shift);
      vec3 i = cone_sample(c, cos_r, u);
      if (dot(ng, i) <= 0.0) {
        continue;
      }
      vec3 f = vec3(0.0);
      if (kd.w > 0.5 && !clear) {
        f += kd.rgb * wd * max(dot(nd, i), 0.0) * (omega / float(NL)) *
             (mapped ? bump_shadowing(smoothN, nd, i) : 1.0);
      }
      if (lobeSampled) {
        float pl = 1.0 / omega;
        float pb = ndf_pdf(n, o, i, a, dist);
        f += glossy_f_cos(n, o, i, cos_o, a, dist, lobes, lam_o, ms0, ms1) /
             (float(NL) * pl + float(NB) * pb);
      }
      sum += f * L;
    }
    if (lobeSampled) {
      for (int b = 0; b < NB; b++) {
        vec3 i;
        if (!ndf_direction(b, n, o, a, dist, tx, ty, shift, i) ||
            dot(i, c) < cos_r || dot(ng, i) <= 0.0) {
          continue;                               /* misses the disc */
        }
        float pb = ndf_pdf(n, o, i, a, dist);
        sum += glossy_f_cos(n, o, i, cos_o, a, dist, lobes, lam_o, ms0, ms1) * L /
               (float(NL) / omega + float(NB) * pb);
      }
    }
  }
  return V * sum;
}


/* ---------------------------------------------------------------- main */

void main()
{
  float texAlpha = textured_alpha();
  float closedSide = param(9, 0).x;
  if (other_copy(closedSide)) discard;
  int sourceCount = textureSize(srcTex, 0).y;
  if (inner_side(closedSide) || sourceCount == 0) {
    fragColor = vec4(0.0);
    return;
  }
  vec3 n = normalize(vNrm);
  vec3 ng = normalize(cross(dFdx(vPos), dFdy(vPos)));
  ng = dot(ng, n) < 0.0 ? -ng : ng;
  /* a normal or bump map: the Lambert and glossy terms use the mapped normal (the glossy
   * one corrected below), visibility and the horizon tests the surface's */
#ifdef NORMAL_MAP
  vec4 nmap = texelFetch(paramTex, ivec2(16, 0), 0);
  bool mapped = nmap.x > 0.5;
  if (mapped) {
    n = mapped_normal(normalTex, vUv, vPos, vNrm, vTng.xyz, vTng.w, nmap,
                      texelFetch(paramTex, ivec2(17, 0), 0),
                      texelFetch(paramTex, ivec2(18, 0), 0).xyz,
                      texelFetch(paramTex, ivec2(19, 0), 0).xyz,
                      texelFetch(paramTex, ivec2(20, 0), 0));
  }
#else
  const bool mapped = false;
#endif
  vec3 nd = n;                             /* the diffuse term's normal: never corrected */
  mappedN = mapped;
  smoothN = normalize(vNrm);
  vec4 eye = param(8, 0);
  vec3 o = view_direction(eye, vPos);
  /* Cycles turns every glossy closure's normal until the mirror reflection clears the
   * triangle (ensure_valid_specular_reflection): a smooth normal bent at a crease as much
   * as a mapped one (the glossy terms only; the sharp pass does the same) */
  if (dot(ng, o) > 0.0) {
    n = valid_reflection_normal(ng, o, n);
  }
  o = bent_view(n, o);
  /* the mirror as the sharp pass takes it (its footprint decides which pass draws a
   * compact source of the World for a mirror-like slot) */
  mirror = reflect(-o, n);
  mdx = dFdx(mirror);
  mdy = dFdy(mirror);
  pdx = dFdx(vPos);
  pdy = dFdy(vPos);
  float cos_o = clamp(dot(n, o), COS_VIEW_MIN, 1.0);
  vec4 kd = param(0, 0);
#ifdef ALBEDO_TEX
  if (texInfo.z > -0.5 && kd.w > 0.5) {          /* the slot's colour, per pixel / pi */
    kd.rgb = input_colour(albedoTex, vUv, vAttr, texInfo, texMap0, texMap1, mixColor) / PI;
  }
#endif
  vec4 lobe = param(1, 0);
  float a = texAlpha > 0.0 ? texAlpha : max(lobe.x, MICROFACET_ALPHA_MIN);
  int dist = SIG_DIST(int(lobe.y + 0.5));       /* + 0.5: a mix of the roughness nodes' rows */
  /* where the samples sample the lobe (area lamps, discs wider than the footprint, mapped
   * normals) it is widened to the footprint's variance (a box's |dx x dy| / 12 per axis
   * against the lobe's 2 alpha^2), so a shape's edge is the pixel's share of it; a0 the
   * slot's own */
  float a0 = a;
  a = max(a, sqrt(length(cross(mdx, mdy)) / 24.0));
  int lobes = SIG_COUNT(int(lobe.z + 0.5));
  read_lobes(lobes);
#ifdef GLOSSY
  bool glossy = lobe.w > 0.5 && lobes > 0;
  bool sharpSlot = param(9, 0).y > 0.5;
#else
  const bool glossy = false;
  const bool sharpSlot = false;
#endif
  vec3 wd = table(1, cos_o);
  vec3 ms0 = table(2, cos_o), ms1 = table(3, cos_o);
  float lam_o = smith_lambda(dist, a, cos_o);
  /* the lobes' whole reflectance (f cos over the sampling pdf at the mirror: F G for a
   * narrow lobe), for the highlights narrower than the footprint's shorter side (reach2),
   * drawn through it */
  float reach2 = through_reach2(mdx, mdy, mapped);
  float ndf_peak = glossy && reach2 > 0.0 ? ndf_pdf(n, o, mirror, a, dist) : 0.0;
  vec3 spec_w = ndf_peak > 0.0 ?
      glossy_f_cos(n, o, mirror, cos_o, a, dist, lobes, lam_o, ms0, ms1) / ndf_peak : vec3(0.0);
  vec3 tx, ty;
  tangent_frame(n, tx, ty);
  vec2 shift = pixel_shift();
  vec3 color = vec3(0.0);
  /* the lights of each group this pixel loops over, in srcTex's order: with LIGHT_TILES
   * those that can reach its screen tile (addon/gpu/light_tiles.py: per tile a texel (each
   * group's count) and the indices four a texel; the last row's first texel the viewport's
   * origin, the tile size and the texels per tile), else all (srcTex row 0's COUNT_TEXEL) */
#ifdef LIGHT_TILES
  ivec2 tiles = textureSize(tileTex, 0);
  vec4 tinfo = texelFetch(tileTex, ivec2(0, tiles.y - 1), 0);
  int stride = int(tinfo.w);
  ivec2 cell = clamp(ivec2((gl_FragCoord.xy - tinfo.xy) / tinfo.z), ivec2(0),
                     ivec2(tiles.x / stride - 1, tiles.y - 2));
  int base = cell.x * stride;
  ivec3 counts = ivec3(texelFetch(tileTex, ivec2(base, cell.y), 0).xyz + 0.5);
#define LIGHT(k) int(texelFetch(tileTex, ivec2(base + 1 + (k) / 4, cell.y), 0)[(k) % 4])
#else
  ivec3 counts = ivec3(source(0, COUNT_TEXEL).xyz + 0.5);
#define LIGHT(k) (k)
#endif
  for (int k = 0; k < counts.x; k++) {
    color += light_term(DISTANT_GROUP, LIGHT(k),
                        n, nd, ng, o, cos_o, kd, wd, a, a0, dist, lobes, glossy, sharpSlot,
                        mapped, lam_o, ms0, ms1, reach2, spec_w, tx, ty, shift);
  }
#ifdef LOCAL_LAMPS
  for (int k = counts.x; k < counts.x + counts.y; k++) {
    color += light_term(LOCAL_GROUP, LIGHT(k),
                        n, nd, ng, o, cos_o, kd, wd, a, a0, dist, lobes, glossy, sharpSlot,
                        mapped, lam_o, ms0, ms1, reach2, spec_w, tx, ty, shift);
  }
#endif
#ifdef AREA_LAMPS
  for (int k = counts.x + counts.y; k < counts.x + counts.y + counts.z; k++) {
    color += light_term(AREA_GROUP, LIGHT(k),
                        n, nd, ng, o, cos_o, kd, wd, a, a0, dist, lobes, glossy, sharpSlot,
                        mapped, lam_o, ms0, ms1, reach2, spec_w, tx, ty, shift);
  }
#endif
  fragColor = vec4(max(color, vec3(0.0)), 0.0);
}
