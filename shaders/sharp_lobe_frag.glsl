/* Glossy lobes narrower than the cubemap's texels (mirror-like Glossy, Principled
 * specular and metal at low roughness), drawn per pixel and added to the frame.
 *
 * The lobe integral  sum over lobes  w F(h.i) D G2 / (4 cos_o) L(i) V(i)  is estimated
 * with K samples of the NDF (h ~ D(h) n.h): each sample's weight is F G2 (o.h) /
 * (cos_o n.h) (Walter et al. 2007), L(i) is the environment averaged over the sample's
 * share of the lobe (filtered importance sampling, Krivanek & Colbert 2008: the mip level
 * whose texel spans 1 / (K pdf)), and V(i) is the shading points' stored visibility at
 * i, mixed barycentrically.  At alpha = 0 (Cycles' singular reflection) one sample at the
 * mirror direction gives F(cos_o) L(r) V(r) exactly.
 *
 * paramTex texels: 0 eye (xyz, w = 1 perspective / 0 direction toward the viewer),
 * 1 (alpha, distribution 0 Beckmann / 1 GGX, lobe count, samples K), 2 (W0, H0, levels
 * below level 0, strength), 3 (cube N, visibility texels per point), then per lobe
 * (kind, weight, eta, -), (f0 rgb, -), (B rgb, -); kinds: 0 F = f0, 1 Schlick,
 * 2 Principled dielectric, 3 F82-tint (core.brdf.sharp_lobes). */

#define PI 3.14159265358979
#define COS_VIEW_MIN 1e-4
#define LOD_BIAS -2.0


vec4 param(int i)
{
  return texelFetch(paramTex, ivec2(i, 0), 0);
}

/* ---------------------------------------------------------------- microfacet terms */

float ndf(int dist, float a, float c)
{
  float c2 = c * c;
  float a2 = max(a * a, 1e-14);
  if (dist == 0) {
    return exp(-(1.0 - c2) / (max(c2, 1e-30) * a2)) / (PI * a2 * c2 * c2);
  }
  float d = (1.0 - c2) + a2 * c2;
  return a2 / (PI * d * d);
}

float smith_lambda(int dist, float a, float c)
{
  float t2 = a * a * max(1.0 / max(c * c, 1e-24) - 1.0, 0.0);
  if (dist == 0) {
    if (t2 < 0.39) {        /* a = 1 / sqrt(t2) > 1.6: Walter et al.'s rational fit is 0 */
      return 0.0;
    }
    float b = inversesqrt(t2);
    return ((0.396 * b - 1.259) * b + 1.0) / ((2.181 * b + 3.535) * b);
  }
  return 0.5 * (sqrt(1.0 + t2) - 1.0);
}

float fresnel_dielectric(float c, float eta)
{
  c = abs(c);
  float g = eta * eta - 1.0 + c * c;
  if (g <= 0.0) {
    return 1.0;
  }
  g = sqrt(g);
  float A = (g - c) / (g + c);
  float B = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
  return 0.5 * A * A * (1.0 + B * B);
}

vec3 lobe_fresnel(int kind, vec3 f0, vec3 B, float eta, float c)
{
  float s = clamp(1.0 - c, 0.0, 1.0);
  float s5 = s * s * s * s * s;
  if (kind == 0) {
    return f0;
  }
  if (kind == 1) {
    return f0 + (1.0 - f0) * s5;
  }
  if (kind == 2) {
    float F0 = (eta - 1.0) / (eta + 1.0);
    F0 *= F0;
    float r = F0 < 1.0 - 1e-12 ? clamp((fresnel_dielectric(c, eta) - F0) / (1.0 - F0), 0.0, 1.0)
                               : 1.0;
    return f0 + (1.0 - f0) * r;
  }
  return clamp(f0 + (1.0 - f0) * s5 - B * c * s5 * s, 0.0, 1.0);
}

/* ---------------------------------------------------------------- environment */

/* level l (>= 1) of the mip atlas: its size and first row (core.envmap.equirect_mip_sizes) */
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

vec3 env_fetch(int l, int x, int y, int row)
{
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

/* the environment averaged over solid angle `omega` around world direction d */
vec3 env_filtered(vec3 d, float omega)
{
  vec3 t = envRot * d;
  float u = fract(0.5 - atan(t.y, t.x) / (2.0 * PI));
  float ct = clamp(t.z, -1.0, 1.0);
  float v = acos(ct) / PI;
  vec4 info = param(2);
  float texel = (2.0 * PI / info.x) * (PI / info.y) * max(sqrt(1.0 - ct * ct), 0.5 / info.y);
  float lod = omega > 0.0 ? clamp(0.5 * log2(omega / texel) + LOD_BIAS, 0.0, info.z) : 0.0;
  int l0 = int(floor(lod));
  float f = lod - float(l0);
  vec3 c = env_level(l0, vec2(u, v));
  if (f > 0.0 && l0 + 1 <= int(info.z)) {
    c = mix(c, env_level(l0 + 1, vec2(u, v)), f);
  }
  return c * info.w;
}

/* ---------------------------------------------------------------- stored visibility */

/* bit of cubemap texel k of shading point p (core.visibility: np.packbits, 3 bytes per
 * float, 4 floats per texel) */
float visible_bit(float p, int k)
{
  int stride = int(param(3).y);
  int byte_index = k >> 3;
  int fi = byte_index / 3;
  int idx = int(p + 0.5) * stride + fi / 4;
  vec4 word4 = texelFetch(visTex, ivec2(idx % 4096, idx / 4096), 0);
  int value = int(word4[fi % 4]);     /* exact integers below 2^24: no rounding offset */
  int octet = (value >> (16 - 8 * (byte_index % 3))) & 255;
  return float((octet >> (7 - (k & 7))) & 1);
}

/* core.directions.texel_of_components */
int cube_texel(vec3 d, int n)
{
  vec3 a = abs(d);
  float s, t, m;
  int face;
  if (a.x >= a.y && a.x >= a.z) {
    m = a.x;
    face = d.x < 0.0 ? 1 : 0;
    s = d.x < 0.0 ? d.z : -d.z;
    t = -d.y;
  }
  else if (a.y >= a.z) {
    m = a.y;
    face = d.y < 0.0 ? 3 : 2;
    s = d.x;
    t = d.y < 0.0 ? -d.z : d.z;
  }
  else {
    m = a.z;
    face = d.z < 0.0 ? 5 : 4;
    s = d.z < 0.0 ? -d.x : d.x;
    t = -d.y;
  }
  m = m > 0.0 ? m : 1.0;
  int col = clamp(int((s / m + 1.0) * 0.5 * float(n)), 0, n - 1);
  int row = clamp(int((t / m + 1.0) * 0.5 * float(n)), 0, n - 1);
  return (face * n + row) * n + col;
}

float visibility(vec3 d)
{
  int k = cube_texel(d, int(param(3).x));
  return vBary.x * visible_bit(vTri.x, k) + vBary.y * visible_bit(vTri.y, k) +
         vBary.z * visible_bit(vTri.z, k);
}

/* ---------------------------------------------------------------- main */

float radical_inverse(int i)
{
  uint b = uint(i);
  b = (b << 16u) | (b >> 16u);
  b = ((b & 0x55555555u) << 1u) | ((b & 0xAAAAAAAAu) >> 1u);
  b = ((b & 0x33333333u) << 2u) | ((b & 0xCCCCCCCCu) >> 2u);
  b = ((b & 0x0F0F0F0Fu) << 4u) | ((b & 0xF0F0F0F0u) >> 4u);
  b = ((b & 0x00FF00FFu) << 8u) | ((b & 0xFF00FF00u) >> 8u);
  return float(b) * 2.3283064365386963e-10;
}

void main()
{
  bool inner = closedSide > 0.5 ? !gl_FrontFacing : (closedSide < -0.5 ? gl_FrontFacing : false);
  if (inner) {
    fragColor = vec4(0.0);
    return;
  }
  vec3 n = normalize(vNrm);
  vec4 eye = param(0);
  vec3 o = eye.w > 0.5 ? normalize(eye.xyz - vPos) : normalize(eye.xyz);
  float cos_o = dot(n, o);
  if (cos_o < COS_VIEW_MIN) {          /* core.brdf._bend_views */
    o = normalize(o + (COS_VIEW_MIN - cos_o) * n);
    cos_o = COS_VIEW_MIN;
  }
  cos_o = clamp(cos_o, COS_VIEW_MIN, 1.0);
  vec4 lobe = param(1);
  float a = lobe.x;
  int dist = int(lobe.y);
  int lobes = int(lobe.z);
  int K = a > 0.0 ? int(lobe.w) : 1;
  /* tangent frame (Duff et al. 2017) */
  float sgn = n.z >= 0.0 ? 1.0 : -1.0;
  float q = -1.0 / (sgn + n.z);
  float r = n.x * n.y * q;
  vec3 tx = vec3(1.0 + sgn * n.x * n.x * q, sgn * r, -sgn * n.x);
  vec3 ty = vec3(r, sgn + n.y * n.y * q, -n.y);
  float lam_o = smith_lambda(dist, a, cos_o);
  vec3 color = vec3(0.0);
  /* the sample set turned per pixel (Cranley-Patterson): neighbouring pixels and F12's
   * supersamples see other parts of the lobe, so the pattern averages out as noise */
  vec2 shift = fract(vec2(0.7548776662, 0.5698402910) * dot(floor(gl_FragCoord.xy), vec2(1.0, 61.0)));
  for (int s = 0; s < K; s++) {
    vec3 h = n;
    if (a > 0.0) {
      float u1 = fract((float(s) + 0.5) / float(K) + shift.x);
      float u2 = fract(radical_inverse(s) + shift.y);
      float tan2 = dist == 0 ? -a * a * log(1.0 - u1) : a * a * u1 / (1.0 - u1);
      float ch = inversesqrt(1.0 + tan2);
      float sh = sqrt(max(1.0 - ch * ch, 0.0));
      float phi = 2.0 * PI * u2;
      h = normalize(tx * (sh * cos(phi)) + ty * (sh * sin(phi)) + n * ch);
    }
    float oh = dot(o, h);
    if (oh <= 0.0) {
      continue;
    }
    vec3 i = 2.0 * oh * h - o;
    float cos_i = dot(n, i);
    if (cos_i <= 0.0) {
      continue;
    }
    float nh = max(dot(n, h), 1e-6);
    float g2 = 1.0 / (1.0 + smith_lambda(dist, a, cos_i) + lam_o);
    /* the sample's solid angle 1 / (K pdf), pdf = D (n.h) / (4 o.h); 0 for a mirror */
    float omega = a > 0.0 ? 4.0 * oh / (float(K) * ndf(dist, a, nh) * nh) : 0.0;
    vec3 light = env_filtered(i, omega) * visibility(i);
    vec3 f = vec3(0.0);
    for (int j = 0; j < lobes; j++) {
      vec4 k0 = param(4 + 3 * j);
      f += k0.y * lobe_fresnel(int(k0.x), param(5 + 3 * j).rgb, param(6 + 3 * j).rgb, k0.z, oh);
    }
    color += f * light * (g2 * oh / (cos_o * nh));
  }
  fragColor = vec4(max(color / float(K), vec3(0.0)), 0.0);
}
