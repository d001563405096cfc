/* Spherical-Gaussian helpers of Wang et al. 2009: functions only, no main.
 *
 * GLSL twin of core/sg/algebra.py (product eq. 5, inner product eq. 4 in the stable form),
 * core/sg/brdf.py (specular_lobes: NDF lobe -> spherical warp eq. 17-21 -> M_o at the
 * lobe centre eq. 22, Fresnel eq. 14) and core/sg/lighting.py
 * (PrefilteredEnvironment.lookup, eq. 34-35).  Every lobe is mu * exp(lam (dot(i, axis) - 1)).
 * tests/test_sg_brdf.py::test_glsl_matches_numpy renders these functions offscreen and
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
 * Prefiltered environment: one RGBA32F 2D texture (PrefilteredEnvironment.atlas()),
 * N texels wide, row (level * 6 + face) * N + row; read with texelFetch, bilinear within
 * a face (edge-clamped) and linear in log lam between levels, like the numpy lookup.
 */

#define SG_MAX_LOBES 8
#define SG_PI 3.14159265358979
#define SG_ALPHA_MIN 0.005
#define SG_COS_MIN 1e-4
#define SG_COS_VIEW_MIN 1e-4
#define SG_COS_MIN_SINGULAR 0.05
#define SG_LAMBDA_MAX 1e5
/* eq. 40's clamped-cosine SG (core.sg.algebra.clamped_cosine_sg) */
#define SG_COSINE_LAMBDA 2.133
#define SG_COSINE_MU 1.17

/* NDF correction tables c_lam, c_mu on a = 0, 0.05, ..., 1 (core.sg.brdf.ISO_NDF_TABLE). */
const float SG_CT_CLAM[21] = float[21](0.9999875, 0.998759, 0.9951434, 0.9894735, 0.9822715, 0.9742365, 0.9661932, 0.9590131, 0.9535198, 0.9504024, 0.9501555, 0.9530325, 0.9589624, 0.9674702, 0.9777121, 0.9886328, 0.9991382, 1.008208, 1.014945, 1.018575, 1.018442);
const float SG_CT_CMU[21] = float[21](1.000009, 1.000942, 1.003824, 1.00881, 1.016176, 1.0263, 1.039642, 1.056713, 1.078028, 1.104056, 1.135187, 1.171698, 1.213695, 1.261066, 1.313499, 1.370577, 1.431874, 1.497024, 1.56574, 1.637814, 1.713104);
const float SG_BP_CLAM[21] = float[21](0.9999875, 0.9987504, 0.9950063, 0.9887823, 0.9801036, 0.9690081, 0.9555488, 0.9397978, 0.9218516, 0.9018378, 0.8799089, 0.8561223, 0.830001, 0.7998931, 0.7626473, 0.7136991, 0.6471314, 0.5553527, 0.4281937, 0.250977, 3.368977e-05);
const float SG_BP_CMU[21] = float[21](1.000003, 1.000313, 1.001261, 1.002869, 1.005181, 1.008263, 1.012208, 1.01714, 1.023227, 1.030694, 1.039831, 1.050948, 1.064152, 1.078992, 1.094267, 1.108047, 1.117649, 1.119314, 1.107412, 1.072862, 1.000034);
const float SG_WARD_CLAM[21] = float[21](1.000038, 1.003747, 1.014944, 1.033472, 1.059136, 1.091688, 1.130836, 1.176271, 1.227673, 1.284734, 1.347164, 1.414696, 1.487091, 1.564131, 1.645614, 1.731344, 1.821123, 1.914752, 2.012031, 2.11276, 2.216747);
const float SG_WARD_CMU[21] = float[21](1.000009, 1.000934, 1.003699, 1.008185, 1.014223, 1.0216, 1.03008, 1.039424, 1.049401, 1.059803, 1.070449, 1.081186, 1.091891, 1.102468, 1.112836, 1.122934, 1.132709, 1.142121, 1.151137, 1.159735, 1.167898);

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
  return 2.0 * SG_PI * sg_one_minus_exp2_over(lam);
}

/* Eq. 4 with unit amplitudes: 4 pi e^{-(l1+l2)} sinh(d_m)/d_m, stable for lam up to 1e5
 * and antipodal lobes. */
float sg_inner_product(vec3 p1, float l1, vec3 p2, float l2)
{
  float dm, defect;
  vec3 dvec;
  sg_defect(p1, l1, p2, l2, dm, defect, dvec);
  return 2.0 * SG_PI * exp(-defect) * sg_one_minus_exp2_over(dm);
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

float sg_table(float table[21], float a)
{
  float x = clamp(a, 0.0, 1.0) * 20.0;
  int i = min(int(x), 19);
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
  lam = max(cl * 2.0 / (a * a), 1e-4);
  mu = cm / (SG_PI * a * a);
}

/* Eq. 14 (Cook-Torrance Fresnel), c = |i.h|, eta the relative IOR. */
float sg_fresnel_eq14(float c, float eta)
{
  c = abs(c);
  float g2 = eta * eta + c * c - 1.0;
  if (g2 <= 0.0) {
    return 1.0;
  }
  float g = sqrt(g2);
  float a = (g - c) / (g + c);
  float b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
  return 0.5 * a * a * (1.0 + b * b);
}

/* ks F(c) = A + B_d F_eq14(c, eta) + B_s (1 - c)^5 (core.sg.brdf.fresnel_coefficients). */
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
  float fd = sg_fresnel_eq14(c, eta);
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

/* Cycles' rational Beckmann Smith Lambda (core.shading.brdf.smith_lambda), a2 = alpha^2. */
float sg_beckmann_lambda(float a2, float c)
{
  c = clamp(c, 1e-12, 1.0);
  float t2 = a2 * max(1.0 / (c * c) - 1.0, 0.0);
  if (t2 < 0.39) {
    return 0.0;
  }
  float a = 1.0 / sqrt(t2);
  return ((0.396 * a - 1.259) * a + 1.0) / ((2.181 * a + 3.535) * a);
}

/* M_o(i) without Fresnel (core.sg.brdf._m_factor). */
float sg_m_factor(int model, float roughness, float cos_i, float cos_o, float h_dot_i)
{
  if (model <= 1) {
    float ci = max(cos_i, SG_COS_MIN);
    float co = max(cos_o, SG_COS_MIN);
    float a = max(roughness, SG_ALPHA_MIN);
    float a2 = a * a;
    float li = sg_beckmann_lambda(a2, ci);
    float lo = sg_beckmann_lambda(a2, co);
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
    float sgn = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (sgn + n.z);
    float bb = n.x * n.y * a;
    t = vec3(1.0 + sgn * n.x * n.x * a, sgn * bb, -sgn * n.x);
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
  float cos_o = dot(n, o);
  if (cos_o < SG_COS_VIEW_MIN) {                   /* bend views below the horizon */
    o = normalize(o + (SG_COS_VIEW_MIN - cos_o) * n);
    cos_o = dot(n, o);
  }
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
 * edge, n_levels: levels in the atlas, lam1: lambdas[1], log_ratio: log(ratio) of the ladder.
 * The inner product of eq. 35 is mu * sg_integral(lam) * prefiltered_lookup(...). */
vec3 prefiltered_lookup(sampler2D atlas, vec3 dir, float lam, int N, int n_levels, float lam1,
                        float log_ratio)
{
  lam = max(lam, 0.0);
  int nf = n_levels - 2;
  float top = lam1 * exp(log_ratio * float(nf - 1));
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

/* Eq. 35: G(i; p, lam, mu) . L. */
vec3 sg_environment_inner_product(sampler2D atlas, vec3 p, float lam, vec3 mu, int N,
                                  int n_levels, float lam1, float log_ratio)
{
  return mu * sg_integral(lam) * prefiltered_lookup(atlas, p, lam, N, n_levels, lam1, log_ratio);
}
