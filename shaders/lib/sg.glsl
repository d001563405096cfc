/* Spherical-Gaussian helpers of Wang et al. 2009: functions only, no main (after
 * constants.glsl, common.glsl and microfacet.glsl: addon/gpu/shaders.py SG_LIBRARY).
 *
 * GLSL twin of core/sg/algebra.py (product eq. 5, inner product eq. 4 in the stable form),
 * core/sg/brdf.py (specular_lobes: NDF lobe -> spherical warp eq. 17-21 -> M_o at the
 * lobe centre eq. 22, Fresnel eq. 14) and core/sg/prefilter.py
 * (PrefilteredEnvironment.lookup, eq. 34-35).  Every lobe is mu * exp(lam (dot(i, axis) - 1)).
 * tests/gpu/test_sg_common.py (test_glsl_*) renders these functions offscreen and
 * compares with numpy.
 *
 * Material parameters of specular_lobes (per pixel; textured values go in here):
 *   sgm0 = (model, fresnel, roughness a, ior)   model: 0 COOK_TORRANCE, 1 BLINN_PHONG, 2 WARD,
 *                                               3 WARD_ANISO, 4 ASHIKHMIN_SHIRLEY;
 *                                               fresnel: 0 NONE, 1 SCHLICK, 2 DIELECTRIC,
 *                                               3 PRINCIPLED  (core.sg.brdf.MODEL_INDEX/FRESNEL_INDEX)
 *   sgm1 = (ks.rgb, metallic)
 *   sgm2 = (base.rgb, unused)                   base = SGMaterial.diffuse (PRINCIPLED metal F0)
 *   ndf_lobes[k] = (axis in the local frame (t, b, n), lam), ndf_mu[k] = mu, k < n_ndf:
 *                                               the anisotropic fit of core.sg.brdf.ndf_lobes
 *                                               (unused by the isotropic models: n_ndf = 0).
 * Its constants (SG_ALPHA_MIN, the NDF tables SG_CT_CLAM ..., SG_COS_MIN, ...) are in
 * constants.glsl, generated from core.sg.ndf.
 * Prefiltered environment: one RGBA32F 2D texture (PrefilteredEnvironment.atlas()),
 * N texels wide, row (level * 6 + face) * N + row; read with texelFetch, bilinear within
 * a face (edge-clamped) and linear in log lam between levels, like the numpy lookup.
 */

/* ---------------------------------------------------------------- SG algebra (core/sg/algebra.py) */

/* G(v; p, lam, 1) with v.p - 1 = -|v - p|^2 / 2 (accurate next to the axis). */
float sg_eval(vec3 v, vec3 p, float lam)
{
  vec3 d = v - p;
  return exp(-0.5 * lam * dot(d, d));
}

/* (1 - exp(-2 x)) / x for x >= 0 (limit 2 at 0), without cancellation. */
float sg_one_minus_exp2_over(float x)
{
  if (x < 1e-3) {
    return 2.0 - 2.0 * x + 4.0 / 3.0 * x * x;
  }
  return (1.0 - exp(-2.0 * x)) / x;
}

/* d_m = |l1 p1 + l2 p2| and the defect l1 + l2 - d_m computed as
 * 2 l1 l2 (1 - cos) / (l1 + l2 + d_m), 1 - cos = |p1 - p2|^2 / 2. */
void sg_defect(vec3 p1, float l1, vec3 p2, float l2, out float dm, out float defect, out vec3 dvec)
{
  dvec = l1 * p1 + l2 * p2;
  dm = length(dvec);
  vec3 diff = p1 - p2;
  float omc = clamp(0.5 * dot(diff, diff), 0.0, 2.0);
  float denom = l1 + l2 + dm;
  defect = denom > 0.0 ? 2.0 * l1 * l2 * omc / denom : 0.0;
}

/* Integral of G(.; p, lam, 1) over the sphere: 2 pi (1 - e^{-2 lam}) / lam. */
float sg_integral(float lam)
{
  return 2.0 * PI * sg_one_minus_exp2_over(lam);
}

/* Eq. 4 with unit amplitudes: 4 pi e^{-(l1+l2)} sinh(d_m)/d_m, stable for lam up to 1e5
 * and antipodal lobes. */
float sg_inner_product(vec3 p1, float l1, vec3 p2, float l2)
{
  float dm, defect;
  vec3 dvec;
  sg_defect(p1, l1, p2, l2, dm, defect, dvec);
  return 2.0 * PI * exp(-defect) * sg_one_minus_exp2_over(dm);
}

/* Eq. 5: G1 G2 = G(.; d/|d|, |d|, mu1 mu2 exp(|d| - l1 - l2)), d = l1 p1 + l2 p2.
 * Returns the amplitude factor exp(|d| - l1 - l2); axis/lam out. */
float sg_product(vec3 p1, float l1, vec3 p2, float l2, out vec3 axis, out float lam)
{
  float dm, defect;
  vec3 dvec;
  sg_defect(p1, l1, p2, l2, dm, defect, dvec);
  axis = dm > 0.0 ? dvec / dm : p1;
  lam = dm;
  return exp(-defect);
}

/* ---------------------------------------------------------------- BRDF (core/sg/brdf.py) */

/* linear between the table's nodes a = i / (SG_TABLE_NODES - 1) (core.sg.ndf.ISO_TABLE_ALPHA) */
float sg_table(float table[SG_TABLE_NODES], float a)
{
  float x = clamp(a, 0.0, 1.0) * float(SG_TABLE_NODES - 1);
  int i = min(int(x), SG_TABLE_NODES - 2);
  float t = x - float(i);
  return (1.0 - t) * table[i] + t * table[i + 1];
}

/* Single-lobe SG of an isotropic NDF (core.sg.brdf.iso_ndf_sg). */
void sg_iso_ndf(int model, float roughness, out float lam, out float mu)
{
  float a = max(roughness, SG_ALPHA_MIN);
  float cl, cm;
  if (model == 0) {
    cl = sg_table(SG_CT_CLAM, a);
    cm = sg_table(SG_CT_CMU, a);
  }
  else if (model == 1) {
    cl = sg_table(SG_BP_CLAM, a);
    cm = sg_table(SG_BP_CMU, a);
  }
  else {
    cl = sg_table(SG_WARD_CLAM, a);
    cm = sg_table(SG_WARD_CMU, a);
  }
  lam = max(cl * 2.0 / (a * a), SG_LAMBDA_MIN);
  mu = cm / (PI * a * a);
}

/* ks F(c) = A + B_d F_eq14(c, eta) + B_s (1 - c)^5 (core.sg.brdf.fresnel_coefficients); eq. 14
 * is the Cook-Torrance dielectric Fresnel, microfacet.glsl's fresnel_dielectric. */
vec3 sg_fresnel(int mode, float c, float eta, vec3 ks, float metallic, vec3 base)
{
  c = clamp(c, 0.0, 1.0);
  if (mode == 0) {
    return ks;
  }
  float s5 = pow(1.0 - c, 5.0);
  if (mode == 1) {
    return ks + (1.0 - ks) * s5;
  }
  float fd = fresnel_dielectric(c, eta);
  if (mode == 2) {
    return ks * fd;
  }
  float f0r = min(((eta - 1.0) / (eta + 1.0)) * ((eta - 1.0) / (eta + 1.0)), 1.0 - 1e-6);
  vec3 k = clamp(ks, 0.0, 1.0);
  vec3 b = clamp(base, 0.0, 1.0);
  vec3 A = (1.0 - metallic) * (k - (1.0 - k) * f0r / (1.0 - f0r)) + metallic * b;
  vec3 Bd = (1.0 - metallic) * (1.0 - k) / (1.0 - f0r);
  vec3 Bs = metallic * (1.0 - b);
  return max(A + Bd * fd + Bs * s5, vec3(0.0));
}

/* M_o(i) without Fresnel (core.sg.brdf._m_factor): Cook-Torrance and Blinn-Phong take
 * Cycles' Beckmann Smith Lambda (microfacet.glsl smith_lambda). */
float sg_m_factor(int model, float roughness, float cos_i, float cos_o, float h_dot_i)
{
  if (model <= 1) {
    float ci = max(cos_i, SG_COS_MIN);
    float co = max(cos_o, SG_COS_MIN);
    float a = max(roughness, SG_ALPHA_MIN);
    float li = smith_lambda(0, a, ci);
    float lo = smith_lambda(0, a, co);
    return 1.0 / ((1.0 + li + lo) * 4.0 * ci * co);
  }
  float ci = max(cos_i, SG_COS_MIN_SINGULAR);
  float co = max(cos_o, SG_COS_MIN_SINGULAR);
  if (model <= 3) {
    return 1.0 / (4.0 * sqrt(ci * co));
  }
  return 1.0 / (4.0 * max(h_dot_i, SG_COS_MIN_SINGULAR) * max(ci, co));
}

/* Tangent frame: t made orthogonal to n, or the branchless Duff et al. frame
 * (core.sphere.directions.orthonormal_frame) when t is degenerate. */
void sg_frame(vec3 n, vec3 t_in, out vec3 t, out vec3 b)
{
  vec3 t0 = t_in - dot(t_in, n) * n;
  float len_t = length(t0);
  if (len_t > 1e-8) {
    t = t0 / len_t;
  }
  else {
    vec3 unused;
    tangent_frame(n, t, unused);
  }
  b = cross(n, t);
}

/* The view slice ks rho_s(o, i) as SG lobes (core.sg.brdf.specular_lobes), without the
 * cosine; models 0-4 (GGX, 5, is drawn by ssdf_sg_frag.glsl's ggx_specular).  n, o unit; t a tangent (any vector; vec3(0) for the default frame).
 * Returns the lobe count K (<= SG_MAX_LOBES); lobes k < K are in axes/lams/mus. */
int specular_lobes(vec4 sgm0, vec4 sgm1, vec4 sgm2, vec3 n, vec3 o, vec3 t_in,
                   int n_ndf, vec4 ndf_lobes[SG_MAX_LOBES], float ndf_mu[SG_MAX_LOBES],
                   out vec3 axes[SG_MAX_LOBES], out float lams[SG_MAX_LOBES],
                   out vec3 mus[SG_MAX_LOBES])
{
  int model = int(sgm0.x + 0.5);
  int fresnel = int(sgm0.y + 0.5);
  float roughness = sgm0.z;
  float eta = sgm0.w;
  vec3 t, b;
  sg_frame(n, t_in, t, b);
  int K = model <= 2 ? 1 : min(n_ndf, SG_MAX_LOBES);
  o = bent_view(n, o);                           /* views below the horizon bent up */
  float cos_o = dot(n, o);
  for (int k = 0; k < SG_MAX_LOBES; k++) {
    axes[k] = n;
    lams[k] = 1.0;
    mus[k] = vec3(0.0);
    if (k >= K) {
      continue;
    }
    vec3 p;
    float lam_d, mu_d;
    if (model <= 2) {
      p = n;
      sg_iso_ndf(model, roughness, lam_d, mu_d);
    }
    else {
      p = ndf_lobes[k].x * t + ndf_lobes[k].y * b + ndf_lobes[k].z * n;
      lam_d = ndf_lobes[k].w;
      mu_d = ndf_mu[k];
    }
    float c = dot(o, p);                           /* o.h at the lobe centre */
    vec3 pw = 2.0 * c * p - o;                     /* eq. 18 */
    pw = pw / max(length(pw), 1e-30);
    float tau = max(4.0 * abs(c), 4.0 * SG_COS_MIN); /* eq. 21 */
    float lam_raw = lam_d / tau;                   /* eq. 19 */
    axes[k] = pw;
    lams[k] = min(lam_raw, SG_LAMBDA_MAX);
    if (c > 0.0) {
      float m = sg_m_factor(model, roughness, dot(n, pw), cos_o, c) * (lams[k] / lam_raw);
      mus[k] = mu_d * m * sg_fresnel(fresnel, c, eta, sgm1.rgb, sgm1.a, sgm2.rgb); /* eq. 22 */
    }
  }
  return K;
}

/* ---------------------------------------------------------------- prefiltered environment */

/* Cube face and (s, t) in [-1, 1] (core.sphere.directions convention). */
void sg_face_coordinates(vec3 d, out int face, out float s, out float t)
{
  vec3 a = abs(d);
  vec3 U, V;
  float m;
  if (a.x >= a.y && a.x >= a.z) {
    m = a.x;
    if (d.x >= 0.0) { face = 0; U = vec3(0, 0, -1); V = vec3(0, -1, 0); }
    else { face = 1; U = vec3(0, 0, 1); V = vec3(0, -1, 0); }
  }
  else if (a.y >= a.z) {
    m = a.y;
    if (d.y >= 0.0) { face = 2; U = vec3(1, 0, 0); V = vec3(0, 0, 1); }
    else { face = 3; U = vec3(1, 0, 0); V = vec3(0, 0, -1); }
  }
  else {
    m = a.z;
    if (d.z >= 0.0) { face = 4; U = vec3(1, 0, 0); V = vec3(0, -1, 0); }
    else { face = 5; U = vec3(-1, 0, 0); V = vec3(0, -1, 0); }
  }
  m = m > 0.0 ? m : 1.0;
  s = dot(d, U) / m;
  t = dot(d, V) / m;
}

vec3 sg_atlas_bilinear(sampler2D atlas, int N, int level, int face, float s, float t)
{
  float x = clamp((s + 1.0) * 0.5 * float(N) - 0.5, 0.0, float(N) - 1.0);
  float y = clamp((t + 1.0) * 0.5 * float(N) - 0.5, 0.0, float(N) - 1.0);
  int x0 = clamp(int(floor(x)), 0, N - 1);     /* NaN-safe: no fetch outside the atlas */
  int y0 = clamp(int(floor(y)), 0, N - 1);
  int x1 = min(x0 + 1, N - 1);
  int y1 = min(y0 + 1, N - 1);
  float fx = x - float(x0);
  float fy = y - float(y0);
  int row = (level * 6 + face) * N;
  vec3 a = texelFetch(atlas, ivec2(x0, row + y0), 0).rgb * (1.0 - fx) +
           texelFetch(atlas, ivec2(x1, row + y0), 0).rgb * fx;
  vec3 c = texelFetch(atlas, ivec2(x0, row + y1), 0).rgb * (1.0 - fx) +
           texelFetch(atlas, ivec2(x1, row + y1), 0).rgb * fx;
  return a * (1.0 - fy) + c * fy;
}

/* PrefilteredEnvironment.lookup: kernel-weighted mean radiance around dir (texture space:
 * rotate world directions by the world's R first) for sharpness lam.  N: texels per face
 * edge, n_levels: levels in the atlas, lam1: lambdas[1], log_ratio: log(ratio) of the ladder,
 * top: lambdas[-2] (the last finite level).  The inner product of eq. 35 is
 * mu * sg_integral(lam) * prefiltered_lookup(...). */
vec3 prefiltered_lookup(sampler2D atlas, vec3 dir, float lam, int N, int n_levels, float lam1,
                        float log_ratio, float top)
{
  lam = max(lam, 0.0);
  int nf = n_levels - 2;
  float x;
  if (lam < lam1) {
    x = lam / lam1;
  }
  else if (lam <= top) {
    x = 1.0 + log(lam / lam1) / log_ratio;
  }
  else {
    x = float(nf) + 1.0 - top / lam;
  }
  int l0 = min(int(floor(x)), n_levels - 1);
  int l1 = min(l0 + 1, n_levels - 1);
  float f = x - float(l0);
  int face;
  float s, t;
  sg_face_coordinates(dir, face, s, t);
  return sg_atlas_bilinear(atlas, N, l0, face, s, t) * (1.0 - f) +
         sg_atlas_bilinear(atlas, N, l1, face, s, t) * f;
}
