/* Glossy lobes narrower than the cubemap's texels (mirror-like Glossy, Principled
 * specular and metal at low roughness), drawn per pixel and added to the frame.
 *
 * The lobe integral  sum over lobes  w F(h.i) D G2 / (4 cos_o) L(i) V(i)  is estimated
 * with K samples of the NDF (h ~ D(h) n.h): each sample's weight is F G2 (o.h) /
 * (cos_o n.h) (Walter et al. 2007), L(i) is the environment averaged over the sample's
 * share of the lobe (filtered importance sampling, Krivanek & Colbert 2008: the mip level
 * whose texel spans 1 / (K pdf)), and V(i) is the shading points' stored visibility at
 * i, mixed barycentrically over the corners that traced it.  At alpha = 0 (Cycles'
 * singular reflection) one sample at the mirror direction gives F(cos_o) L(r) V(r)
 * exactly.
 *
 * A textured Roughness is read per pixel (alpha = r^2), a normal or bump map gives the
 * lobes the mapped normal after Cycles' bump map correction (as lights_frag.glsl), and
 * each lobe is scaled by its multiscatter factor at the pixel's roughness and cos_o.
 *
 * paramTex row 0: 0 eye (xyz, w = 1 perspective / 0 direction toward the viewer),
 * 1 (alpha, distribution 0 Beckmann / 1 GGX, lobe count, samples K), 2 (W0, H0, levels
 * below level 0, strength), 3 (cube N, visibility texels per point, the World's compact
 * sources in worldSrcTex (at most 32), -), then per lobe
 * (kind, weight, eta, -), (f0 rgb, -), (B rgb, -); kinds: 0 F = f0, 1 Schlick,
 * 2 Principled dielectric, 3 F82-tint (core.shading.brdf.sharp_lobes); 10 (roughness nodes n:
 * 1 = the slot's roughness, else a textured Roughness at i / (n - 1)), 11-14 its image
 * (texture_lib.glsl's info, mapping rows, mix colour), 15 a normal or bump map (kind 0
 * none / 1 Normal Map / 2 Bump, strength, distance, -), 16-19 its image.  Rows 1 + 2k + j:
 * lobe j's multiscatter factor at roughness node k, over cos_o = i / (TABLE - 1). */

#define TABLE 32
#define LOD_BIAS -2.0


vec4 param(int i)
{
  return texelFetch(paramTex, ivec2(i, 0), 0);
}

/* ---------------------------------------------------------------- environment */

/* level l (>= 1) of the mip atlas: its size and first row (core.sphere.envmap.equirect_mip_sizes) */
void level_size(int l, out int w, out int h, out int row)
{
  w = int(param(2).x);
  h = int(param(2).y);
  row = 0;
  for (int k = 1; k <= l; k++) {
    if (k > 1) {
      row += h;
    }
    w = (w + 1) / 2;
    h = (h + 1) / 2;
  }
}

/* which image env_fetch reads: false the World's residual (the whole World where none of
 * its compact sources is split off), true its compact sources alone */
bool sourcesImage = false;

vec3 env_fetch(int l, int x, int y, int row)
{
  if (sourcesImage) {
    return l == 0 ? texelFetch(sourcesTex, ivec2(x, y), 0).rgb :
                    texelFetch(sourcesMipTex, ivec2(x, row + y), 0).rgb;
  }
  return l == 0 ? texelFetch(envTex, ivec2(x, y), 0).rgb :
                  texelFetch(mipTex, ivec2(x, row + y), 0).rgb;
}

/* bilinear at (u, v) of level l: columns wrap around, rows clamp at the poles */
vec3 env_level(int l, vec2 uv)
{
  int w, h, row;
  level_size(l, w, h, row);
  float x = uv.x * float(w) - 0.5;
  float y = clamp(uv.y * float(h) - 0.5, 0.0, float(h) - 1.0);
  /* indices clamped into the level (a NaN direction converts to any int; a fetch outside
   * the texture is undefined) */
  int x0 = clamp(int(floor(x)), -1, w - 1);
  int y0 = clamp(int(floor(y)), 0, h - 1);
  float fx = x - float(x0);
  float fy = y - float(y0);
  int y1 = min(y0 + 1, h - 1);
  int xa = x0 < 0 ? x0 + w : x0;
  int xb = xa + 1 < w ? xa + 1 : 0;
  vec3 a = env_fetch(l, xa, y0, row) * (1.0 - fx) + env_fetch(l, xb, y0, row) * fx;
  vec3 b = env_fetch(l, xa, y1, row) * (1.0 - fx) + env_fetch(l, xb, y1, row) * fx;
  return a * (1.0 - fy) + b * fy;
}

/* the environment averaged around world direction d over solid angle `omega` (a sample's
 * share of the lobe, read LOD_BIAS levels sharper) or `share` (its share of the pixel's
 * footprint, unbiased: the samples' mip boxes then tile the footprint), the wider */
vec3 env_filtered(vec3 d, float omega, float share)
{
  vec3 t = envRot * d;
  float u = fract(0.5 - atan(t.y, t.x) / (2.0 * PI));
  float ct = clamp(t.z, -1.0, 1.0);
  float v = acos(ct) / PI;
  vec4 info = param(2);
  float texel = (2.0 * PI / info.x) * (PI / info.y) * max(sqrt(1.0 - ct * ct), 0.5 / info.y);
  float lod = omega > 0.0 ? 0.5 * log2(omega / texel) + LOD_BIAS : 0.0;
  lod = share > 0.0 ? max(lod, 0.5 * log2(share / texel)) : lod;
  lod = clamp(lod, 0.0, info.z);
  int l0 = int(floor(lod));
  float f = lod - float(l0);
  vec3 c = env_level(l0, vec2(u, v));
  if (f > 0.0 && l0 + 1 <= int(info.z)) {
    c = mix(c, env_level(l0 + 1, vec2(u, v)), f);
  }
  return c * info.w;
}

/* ---------------------------------------------------------------- stored visibility */

/* bit of cubemap texel k of shading point p (core.scene.visibility: np.packbits, 3 bytes per
 * float, 4 floats per texel) */
float visible_bit(float p, int k)
{
  int stride = int(param(3).y);
  int byte_index = k >> 3;
  int fi = byte_index / 3;
  int idx = int(p + 0.5) * stride + fi / 4;
  vec4 word4 = texelFetch(visTex, row_texel(idx), 0);
  int value = int(word4[fi % 4]);     /* exact integers below 2^24: no rounding offset */
  int octet = (value >> (16 - 8 * (byte_index % 3))) & 255;
  return float((octet >> (7 - (k & 7))) & 1);
}

/* core.sphere.directions.texel_of_components; `centre`: the texel's centre direction
 * (core.sphere.directions.cubemap: a + s U + t V at the texel's centre s, t) */
int cube_texel(vec3 d, int n, out vec3 centre)
{
  vec3 a = abs(d);
  float s, t, m;
  vec3 major, U, V;
  int face;
  if (a.x >= a.y && a.x >= a.z) {
    m = a.x;
    face = d.x < 0.0 ? 1 : 0;
    s = d.x < 0.0 ? d.z : -d.z;
    t = -d.y;
    major = vec3(sign(d.x), 0.0, 0.0);
    U = vec3(0.0, 0.0, d.x < 0.0 ? 1.0 : -1.0);
    V = vec3(0.0, -1.0, 0.0);
  }
  else if (a.y >= a.z) {
    m = a.y;
    face = d.y < 0.0 ? 3 : 2;
    s = d.x;
    t = d.y < 0.0 ? -d.z : d.z;
    major = vec3(0.0, sign(d.y), 0.0);
    U = vec3(1.0, 0.0, 0.0);
    V = vec3(0.0, 0.0, d.y < 0.0 ? -1.0 : 1.0);
  }
  else {
    m = a.z;
    face = d.z < 0.0 ? 5 : 4;
    s = d.z < 0.0 ? -d.x : d.x;
    t = -d.y;
    major = vec3(0.0, 0.0, sign(d.z));
    U = vec3(d.z < 0.0 ? -1.0 : 1.0, 0.0, 0.0);
    V = vec3(0.0, -1.0, 0.0);
  }
  m = m > 0.0 ? m : 1.0;
  int col = clamp(int((s / m + 1.0) * 0.5 * float(n)), 0, n - 1);
  int row = clamp(int((t / m + 1.0) * 0.5 * float(n)), 0, n - 1);
  centre = major + ((float(col) + 0.5) * 2.0 / float(n) - 1.0) * U +
           ((float(row) + 0.5) * 2.0 / float(n) - 1.0) * V;
  return (face * n + row) * n + col;
}

/* The shading points' visibility at d, mixed barycentrically over the corners that
 * traced d's texel: a point stores only its normal's hemisphere (core.scene.visibility, 0
 * elsewhere), and on a smooth-shaded rim a corner's normal can face away from light the
 * pixel does see (a cylinder's bottom ring, tilted down, "shadowed" the softboxes on its
 * side's upper part: highlights 24 % dark) -- untraced is unknown, not blocked. */
float visibility(vec3 d)
{
  vec3 centre;
  int k = cube_texel(d, int(param(3).x), centre);
  /* core.scene.visibility.hemisphere_mask: n . w > 0 at the texel's centre */
  vec3 w = vBary * vec3(dot(vTriN0, centre) > 0.0 ? 1.0 : 0.0,
                        dot(vTriN1, centre) > 0.0 ? 1.0 : 0.0,
                        dot(vTriN2, centre) > 0.0 ? 1.0 : 0.0);
  float total = w.x + w.y + w.z;
  if (total <= 0.0) {
    return 0.0;
  }
  return (w.x * visible_bit(vTri.x, k) + w.y * visible_bit(vTri.y, k) +
          w.z * visible_bit(vTri.z, k)) / total;
}

/* ---------------------------------------------------------------- textured inputs */

/* the pixel's roughness: the textured Roughness (clamped luminance), else the slot's */
float pixel_roughness()
{
#ifdef ROUGH_TEX
  vec3 c = input_colour(roughTex, vUv, vec4(1.0), param(11), param(12).xyz, param(13).xyz,
                        param(14));
  return clamp(dot(c, vec3(0.2126, 0.7152, 0.0722)), 0.0, 1.0);
#else
  return sqrt(param(1).x);
#endif
}

/* lobe j's multiscatter factor at roughness r and cos_o (rows of addon/sharp.py) */
vec3 multiscatter(int j, float r, float cos_o)
{
  int n = int(param(10).x + 0.5);
  float x = clamp(cos_o, 0.0, 1.0) * float(TABLE - 1);
  int i0 = min(int(x), TABLE - 2);
  float fx = x - float(i0);
  float y = n > 1 ? clamp(r, 0.0, 1.0) * float(n - 1) : 0.0;
  int k0 = min(int(y), max(n - 2, 0));
  int k1 = min(k0 + 1, n - 1);
  float fy = y - float(k0);
  int r0 = 1 + 2 * k0 + j, r1 = 1 + 2 * k1 + j;
  vec3 a = mix(texelFetch(paramTex, ivec2(i0, r0), 0).rgb,
               texelFetch(paramTex, ivec2(i0 + 1, r0), 0).rgb, fx);
  vec3 b = mix(texelFetch(paramTex, ivec2(i0, r1), 0).rgb,
               texelFetch(paramTex, ivec2(i0 + 1, r1), 0).rgb, fx);
  return mix(a, b, fy);
}

/* ---------------------------------------------------------------- main */

void main()
{
  if (other_copy(closedSide)) discard;
  if (inner_side(closedSide)) {
    fragColor = vec4(0.0);
    return;
  }
  vec3 n = normalize(vNrm);
  vec3 smoothN = n;
  vec4 eye = param(0);
  vec3 o = view_direction(eye, vPos);
  /* the triangle's own plane, on its shading normal's side: Cycles' reflection closures
   * take no light from below it (a smooth normal bent at a crease otherwise reflects
   * light from behind the face) */
  vec3 ng = normalize(cross(dFdx(vPos), dFdy(vPos)));
  ng = dot(ng, smoothN) < 0.0 ? -ng : ng;
#ifdef NORMAL_MAP
  /* the mapped normal, corrected as Cycles' glossy closures take it; the visibility and
   * the horizon tests stay the surface's */
  vec4 nmap = param(15);
  bool mapped = nmap.x > 0.5;
  if (mapped) {
    n = mapped_normal(normalTex, vUv, vPos, vNrm, vTng.xyz, vTng.w, nmap, param(16),
                      param(17).xyz, param(18).xyz, param(19));
    if (dot(ng, o) > 0.0) {
      n = valid_reflection_normal(ng, o, n);
    }
  }
#else
  const bool mapped = false;
#endif
  if (!mapped && dot(ng, o) > 0.0) {
    n = valid_reflection_normal(ng, o, n);
  }
  float cos_o = clamp(dot(n, o), COS_VIEW_MIN, 1.0);
  o = bent_view(n, o);
  vec4 lobe = param(1);
  float rough = pixel_roughness();
  float a = rough * rough;
  int dist = SIG_DIST(int(lobe.y + 0.5));
  int lobes = SIG_COUNT(int(lobe.z + 0.5));
  /* The (sub)pixel's mirror directions span the parallelogram dx, dy (ray differentials),
   * which Cycles integrates the pixel over.  The lobe already blurs over its own width
   * (std sqrt(2) alpha per axis in reflected directions); what it leaves of the box's
   * variance (|d|^2 / 12) is made up by moving each sample to a point of a box shrunk to
   * that variance, so a lobe narrower than the footprint (a sub-pixel source in a mirror)
   * is integrated over the pixel, not hit or missed per sample; a mirror takes K samples
   * too when it has a footprint. */
  vec3 mirror = reflect(-o, n);
  vec3 dx = dFdx(mirror), dy = dFdy(mirror);
  /* the World's compact sources (worldSrcTex: direction, radius) whose highlight, lobe and
   * disc, is narrower than the footprint's shorter side are drawn by the lights pass
   * (lights_frag.glsl footprint_share): this pass reads the others' pixels only */
  float reach2 = through_reach2(dx, dy, mapped);
  int sourceCount = int(param(3).z);
  uint drawnThere = 0u;
  bool anyKept = false;
  for (int k = 0; k < sourceCount; k++) {
    float r = texelFetch(worldSrcTex, ivec2(k, 0), 0).w;
    if (highlight_spread2(a, r) < reach2) {
      drawnThere |= 1u << uint(k);
    }
    else {
      anyKept = true;
    }
  }
  dx *= sqrt(max(1.0 - 24.0 * a * a / max(dot(dx, dx), 1e-12), 0.0));
  dy *= sqrt(max(1.0 - 24.0 * a * a / max(dot(dy, dy), 1e-12), 0.0));
  float footprint = length(cross(dx, dy));
  int K = (a > 0.0 || footprint > 0.0) ? int(lobe.w) : 1;
  vec3 ms[2];
  for (int j = 0; j < min(lobes, 2); j++) {
    ms[j] = multiscatter(j, rough, cos_o);
  }
  vec3 tx, ty;
  tangent_frame(n, tx, ty);
  float lam_o = smith_lambda(dist, a, cos_o);
  vec3 color = vec3(0.0);
  vec2 shift = pixel_shift();      /* the sample set turned per pixel */
  for (int s = 0; s < K; s++) {
    vec3 h = n;
    if (a > 0.0) {
      vec2 u = fract(vec2((float(s) + 0.5) / float(K), radical_inverse(s)) + shift);
      h = sample_ndf(dist, a, u, n, tx, ty);
    }
    float oh = dot(o, h);
    if (oh <= 0.0) {
      continue;
    }
    vec3 i = 2.0 * oh * h - o;
    float cos_i = dot(n, i);
    /* a mapped normal's light from below the smooth normal's horizon reaches no closure,
     * nor light from below the triangle's plane */
    if (cos_i <= 0.0 || (mapped && dot(smoothN, i) * dot(smoothN, n) < 0.0) ||
        dot(ng, i) <= 0.0) {
      continue;
    }
    float nh = max(dot(n, h), 1e-6);
    float g2 = 1.0 / (1.0 + smith_lambda(dist, a, cos_i) + lam_o);
    /* the sample's solid angle 1 / (K pdf), pdf = D (n.h) / (4 o.h), 0 for a mirror, or
     * its share of the footprint */
    float omega = a > 0.0 ? 4.0 * oh / (float(K) * ndf(dist, a, nh) * nh) : 0.0;
    /* read at a point of the footprint (an R2 sequence, turned per pixel unlike the
     * NDF's samples); the horizon tests above are the fragment's own */
    vec2 at = fract(float(s) * vec2(0.7548776662, 0.5698402910) + shift.yx) - 0.5;
    vec3 seen = normalize(i + at.x * dx + at.y * dy);
    vec3 light = env_filtered(seen, omega, footprint / float(K));
    if (anyKept) {
      /* the sources' image there is the nearest source's */
      int nearest = 0;
      float best = -2.0;
      for (int k = 0; k < sourceCount; k++) {
        float c = dot(seen, texelFetch(worldSrcTex, ivec2(k, 0), 0).xyz);
        if (c > best) {
          best = c;
          nearest = k;
        }
      }
      if ((drawnThere & (1u << uint(nearest))) == 0u) {
        sourcesImage = true;
        light += env_filtered(seen, omega, footprint / float(K));
        sourcesImage = false;
      }
    }
    light *= visibility(seen);
    vec3 f = vec3(0.0);
    for (int j = 0; j < min(lobes, 2); j++) {
      vec4 k0 = param(4 + 3 * j);
      f += k0.y * ms[j] *
           lobe_fresnel(j == 0 ? SIG_KIND0(int(k0.x + 0.5)) : SIG_KIND1(int(k0.x + 0.5)),
                        param(5 + 3 * j).rgb, param(6 + 3 * j).rgb, k0.z, oh);
    }
    color += f * light * (g2 * oh / (cos_o * nh));
  }
  fragColor = vec4(max(color / float(K), vec3(0.0)), 0.0);
}
