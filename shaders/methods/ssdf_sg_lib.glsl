/* SSDF_SG per-pixel shading (Wang, Ren, Gong, Snyder, Guo 2009):
 *   radiance = kd R_d + R_s(o)
 *   R_d    = sum_j (C*(i; n) (x) L*_j) . V^d            eq. 39 (f_h of eq. 30, fit eq. 47-49)
 *   R_s(o) = sum   ((C* (x) rho*_s(i; o)) (x) V^d) . L   eq. 41 (eq. 31, Gamma_L of eq. 35)
 * GLSL twin of core/methods/ssdf_sg/shading.py (same formulas and the same texel arithmetic:
 * bilinear SSDF lookups by texelFetch in the Shirley-Chiu square, the prefiltered
 * pyramid's level/face interpolation of core/sg/prefilter.py PrefilteredEnvironment).
 *
 * Textures: coeffTex  per point (1, w_1..w_K) packed 4 per texel, coeffTexels texels
 *                     per point, rows of ROW_TEXELS texels;
 *           eigenTex  2D array, layer l = SSDF images 4l..4l+3 (mean, E_1, ..., E_K);
 *           envTex    prefiltered atlas, row (level * 6 + face) * envRes + row;
 *           lightTex  per diffuse lobe j: texel (0, j) = (axis, lam), (1 + m, j) = (mu, 0) as
 *                     seen by clamped-cosine lobe m (the scene fit: one amplitude per pair)
 *                     in texture space (world axis = R^T axis, amplitude * strength);
 *           pairTex   (FLAT_PAIRS) per flat point: the pair table of ssdf_sg_pairs_frag.glsl;
 *           flatTex   (pair pass) per flat point (normal, point index);
 *           paramTex  9 texels of scalar parameters (environment, SSDF, material slot),
 *                     read into the globals below (push constants are kept to 128 bytes),
 *                     texel 9 = (cosine lobe count, sharpness), from INPUT_TEXEL the slot's
 *                     textured inputs (colour, roughness, metallic, specular IOR level; four
 *                     texels each: texture.glsl's info, mapping rows, mix colour), TABLE_TEXEL
 *                     the table's (roughness nodes, level nodes, metallic at its corners 0, 1),
 *                     NORMAL_TEXEL a normal map's (kind, strength, distance),
 *                     texels COSINE_TEXEL.. = (local direction, amplitude) of the
 *                     clamped-cosine SG mixture C*; rows 1..: the slot's table
 *                     (addon/methods/ssdf_sg/gpu.py slot_table): per level node a row, per
 *                     roughness node ENTRY_TEXELS texels: (lambda a^2, mu a^2, eta, -), kd, A,
 *                     B_d, B_s at the (metallic, base colour) corners 00, 01, 10, 11; from
 *                     GGX_TEXEL (-, -, E_avg, multiscatter), E(r, mu) at GGX_E_NODES mu nodes,
 *                     (metal part of A, F_ss main, F_ss metal) per corner; from WARP_TEXEL the
 *                     GGX view slice's lobes (core.sg.ggx_warp.ggx_warp_params) at WARP_MU_NODES
 *                     n.o nodes, three texels a node: the WARP_LOBES_MAX lobes' tilts,
 *                     log-sharpness factors, shares; from LAYER_TEXEL the Lambert base's view
 *                     ratio at the GGX_E_NODES mu nodes.  The texel layout and the numerics'
 *                     constants are in constants.glsl, generated from the Python. */

int cosLobes;
float cosLambda;
int lightCount, ssdfRes, coeffTexels, envRes, envLevels, glossy, brdfModel, principled;
float envStrength, envLambdaFirst, envRatio, envTop, roughness, ior, ndfLambda, ndfMu;
vec4 kd, fresA, fresBd, fresBs, eye;
/* GGX (brdfModel 3): the metal part of A, the two F_ms, and where the pixel's table entry
 * is (for E(r, mu), the view slice's lobes) */
float entryX, entryY;
int tableNr, tableNl;
vec3 fresAm, fmsMain, fmsMetal;


void read_parameters()
{
  vec4 p0 = texelFetch(paramTex, ivec2(0, 0), 0);
  vec4 p1 = texelFetch(paramTex, ivec2(1, 0), 0);
  vec4 p2 = texelFetch(paramTex, ivec2(2, 0), 0);
  vec4 p3 = texelFetch(paramTex, ivec2(3, 0), 0);
  envStrength = p0.x;
  lightCount = int(p0.y + 0.5);
  ssdfRes = int(p0.z + 0.5);
  coeffTexels = int(p0.w + 0.5);
  envRes = int(p1.x + 0.5);
  envLevels = int(p1.y + 0.5);
  envLambdaFirst = p1.z;
  envRatio = p1.w;
  envTop = p2.x;
  glossy = int(p2.y + 0.5);
  brdfModel = int(p2.z + 0.5);
  principled = int(p2.w + 0.5);
  roughness = p3.x;
  ior = p3.y;
  ndfLambda = p3.z;
  ndfMu = p3.w;
  kd = texelFetch(paramTex, ivec2(4, 0), 0);
  fresA = texelFetch(paramTex, ivec2(5, 0), 0);
  fresBd = texelFetch(paramTex, ivec2(6, 0), 0);
  fresBs = texelFetch(paramTex, ivec2(7, 0), 0);
  eye = texelFetch(paramTex, ivec2(8, 0), 0);
  vec4 p9 = texelFetch(paramTex, ivec2(9, 0), 0);
  cosLobes = int(p9.x + 0.5);
  cosLambda = p9.y;   /* (position, 1) or (direction to camera, 0) */
}

/* ------------------------------------------------------------ SG helpers (core/sg/algebra.py) */
float one_minus_exp_neg_over(float lam, float x)   /* (1 - exp(-lam x)) / lam */
{
  return lam > 1e-6 ? (1.0 - exp(-lam * x)) / lam : x;
}

float sg_hemisphere_integral(float lam) { return 2.0 * PI * one_minus_exp_neg_over(lam, 1.0); }

/* standard normal CDF (core.sg.algebra.normal_cdf: erfc of Abramowitz & Stegun 7.1.26) */
float normal_cdf(float z)
{
  float x = abs(z) * 0.7071067811865476;
  float t = 1.0 / (1.0 + 0.3275911 * x);
  float y = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 +
                                                                          t * 1.061405429))));
  float half_erfc = 0.5 * y * exp(-x * x);
  return z >= 0.0 ? 1.0 - half_erfc : half_erfc;
}

/* eq. 47-48 refitted (core/sg/algebra.py): f_h(theta_d, lam) / f_h(pi/2, lam) ~ Phi(k theta_d)
 * scaled to 0 and 1 at theta_d = -pi/2, pi/2; k^2 = lam + c0 - b lam / (lam + d) */
float fh_slope(float lam)
{
  float l = max(lam, 0.0);
  return sqrt(max(l + FH_COEFFS.x - FH_COEFFS.y * l / (l + FH_COEFFS.z), 1e-12));
}

float fh_hat_slope(float theta_d, float k)
{
  float low = normal_cdf(-0.5 * PI * k);
  return clamp((normal_cdf(k * clamp(theta_d, -0.5 * PI, 0.5 * PI)) - low) / (1.0 - 2.0 * low),
               0.0, 1.0);
}

float fh_hat(float theta_d, float lam) { return fh_hat_slope(theta_d, fh_slope(lam)); }

/* ------------------------------------------------------------ SSDF (core/methods/ssdf_sg/ssdf.py) */
void ssdf_frame(vec3 n, out vec3 t, out vec3 b)
{
  vec3 ref = abs(dot(n, FRAME_REF)) > FRAME_SWITCH ? FRAME_REF_ALT : FRAME_REF;
  t = cross(ref, n);
  t = t / max(length(t), 1e-30);
  b = cross(n, t);
}

vec2 square_coordinates(vec3 d)
{
  float z = clamp(d.z, 0.0, 1.0);
  float r = sqrt(1.0 - z);
  float x = d.x, y = d.y;
  if (x == 0.0 && y == 0.0) {
    return vec2(0.5, 0.5);
  }
  float phi = atan(y, x);
  float a, b;
  if (abs(x) >= abs(y)) {
    float phix = x >= 0.0 ? phi : (phi >= 0.0 ? phi - PI : phi + PI);
    a = x >= 0.0 ? r : -r;
    b = a * (4.0 / PI) * phix;
  }
  else {
    float phiy = y >= 0.0 ? 0.5 * PI - phi : -0.5 * PI - phi;
    b = y >= 0.0 ? r : -r;
    a = b * (4.0 / PI) * phiy;
  }
  return vec2(0.5 * (a + 1.0), 0.5 * (b + 1.0));
}

/* the SSDF square's bilinear cell at uv (GL clamp to edge): texels (x0, y0, x1, y1), the
 * weights f, and per axis the slope factor of the square's coordinate (its resolution, or 0
 * in the outer half texel where the lookup is clamped flat) */
void ssdf_cell(vec2 uv, out ivec4 cell, out vec2 f, out vec2 slope)
{
  float n = float(ssdfRes);
  vec2 raw = uv * n - 0.5;
  vec2 xy = clamp(raw, 0.0, n - 1.0);
  int x0 = clamp(int(floor(xy.x)), 0, max(ssdfRes - 2, 0));   /* NaN-safe: no fetch outside */
  int y0 = clamp(int(floor(xy.y)), 0, max(ssdfRes - 2, 0));
  f = xy - vec2(float(x0), float(y0));
  cell = ivec4(x0, y0, min(x0 + 1, ssdfRes - 1), min(y0 + 1, ssdfRes - 1));
  slope = vec2(raw.x == xy.x ? n : 0.0, raw.y == xy.y ? n : 0.0);
}

/* the SSDF's continuation below the horizon: the elevation under it (core.methods.ssdf_sg.shading) */
float ssdf_horizon(vec3 d) { return asin(clamp(-d.z, 0.0, 1.0)); }

/* SSDF value (eq. 24 reconstruction) at a local direction: bilinear per eigen-image
 * layer, combined with the interpolated weights W (first weight 1 = the mean). */
float ssdf_value(vec3 local, vec4 W[16])
{
  ivec4 c;
  vec2 f, flat_;
  ssdf_cell(square_coordinates(local), c, f, flat_);
  float v = 0.0;
  for (int l = 0; l < coeffTexels; l++) {
    vec4 e = texelFetch(eigenTex, ivec3(c.x, c.y, l), 0) * ((1.0 - f.x) * (1.0 - f.y)) +
             texelFetch(eigenTex, ivec3(c.z, c.y, l), 0) * (f.x * (1.0 - f.y)) +
             texelFetch(eigenTex, ivec3(c.x, c.w, l), 0) * ((1.0 - f.x) * f.y) +
             texelFetch(eigenTex, ivec3(c.z, c.w, l), 0) * (f.x * f.y);
    v += dot(e, W[l]);
  }
  return v - ssdf_horizon(local);
}

/* ssdf_value and its derivatives d1, d2 along the unit tangents e1, e2 at local
 * (core.methods.ssdf_sg.shading.theta_d_slopes): the bilinear cell's slope in the square, the map from
 * directions to the square differenced over SLOPE_STEP. */
float ssdf_value_slopes(vec3 local, vec3 e1, vec3 e2, vec4 W[16], out float d1, out float d2)
{
  vec2 uv = square_coordinates(local);
  ivec4 c;
  vec2 f, slope;
  ssdf_cell(uv, c, f, slope);
  float v = 0.0, du = 0.0, dv = 0.0;
  for (int l = 0; l < coeffTexels; l++) {
    vec4 e00 = texelFetch(eigenTex, ivec3(c.x, c.y, l), 0);
    vec4 e10 = texelFetch(eigenTex, ivec3(c.z, c.y, l), 0);
    vec4 e01 = texelFetch(eigenTex, ivec3(c.x, c.w, l), 0);
    vec4 e11 = texelFetch(eigenTex, ivec3(c.z, c.w, l), 0);
    v += dot(e00 * ((1.0 - f.x) * (1.0 - f.y)) + e10 * (f.x * (1.0 - f.y)) +
             e01 * ((1.0 - f.x) * f.y) + e11 * (f.x * f.y), W[l]);
    du += dot((e10 - e00) * (1.0 - f.y) + (e11 - e01) * f.y, W[l]);
    dv += dot((e01 - e00) * (1.0 - f.x) + (e11 - e10) * f.x, W[l]);
  }
  du *= slope.x;
  dv *= slope.y;
  float hor = ssdf_horizon(local);
  vec3 q = normalize(local + SLOPE_STEP * e1);
  vec2 uq = square_coordinates(q);
  d1 = (du * (uq.x - uv.x) + dv * (uq.y - uv.y) - (ssdf_horizon(q) - hor)) / SLOPE_STEP;
  q = normalize(local + SLOPE_STEP * e2);
  uq = square_coordinates(q);
  d2 = (du * (uq.x - uv.x) + dv * (uq.y - uv.y) - (ssdf_horizon(q) - hor)) / SLOPE_STEP;
  return v - hor;
}

vec4 coeff_fetch(float point, int l)
{
  int idx = int(point + 0.5) * coeffTexels + l;
  return texelFetch(coeffTex, row_texel(idx), 0);
}

/* ------------------------------------------------------------ prefiltered environment */
/* kernel-weighted mean radiance of the (unrotated, unit strength) environment */
vec3 env_lookup(vec3 world_dir, float lam)
{
  return prefiltered_lookup(envTex, envRot * world_dir, lam, envRes, envLevels, envLambdaFirst,
                            log(envRatio), envTop);
}

/* Eq. 41's term of one product lobe (p, lam) with unit amplitude, without the world's
 * strength: eq. 31's visible fraction times Gamma_L read at the lobe of the part the SSDF
 * leaves visible (core.methods.ssdf_sg.shading.visible_lobe: the truncated Gaussian's mean and spread). */
vec3 visible_lighting(vec3 p, float lam, vec3 t, vec3 b, vec3 n, vec4 W[16])
{
  vec3 local = vec3(dot(p, t), dot(p, b), dot(p, n));
  vec3 e1, e2;
  sg_frame(local, vec3(0.0), e1, e2);
  float d1, d2;
  float theta = ssdf_value_slopes(local, e1, e2, W, d1, d2);
  float s = inversesqrt(lam);
  float z = clamp(theta / s, Z_RANGE.x, Z_RANGE.y);
  float h = exp(-0.5 * z * z) * 0.3989422804014327 / max(normal_cdf(z), 1e-30);
  float var = s * s * max(1.0 - z * h - h * h, SPREAD_MIN);
  float len = length(vec2(d1, d2));
  float shift = len < 1e-6 ? 0.0 : min(s * h, SHIFT_MAX);
  vec2 g = len < 1e-6 ? vec2(0.0) : vec2(d1, d2) / len;
  vec3 c = cos(shift) * local + sin(shift) * (g.x * e1 + g.y * e2);
  vec3 cw = c.x * t + c.y * b + c.z * n;
  return fh_hat(theta, lam) * sg_integral(lam) * env_lookup(cw, 2.0 / (s * s + var));
}

/* ------------------------------------------------------------ BRDF view slice (core/sg/brdf.py) */
/* M_o(i) of the slot's model (sg.glsl's sg_m_factor; brdfModel 0 CT/Blinn-Phong,
 * 1 Ward, 2 Ashikhmin-Shirley -> core.sg.brdf.MODEL_INDEX 0, 2, 4) */
float m_factor(float cos_i, float cos_o, float h_dot_i)
{
  return sg_m_factor(brdfModel == 0 ? 0 : (brdfModel == 1 ? 2 : 4), roughness, cos_i, cos_o,
                     h_dot_i);
}

/* ------------------------------------------------------------ eq. 39, one pair */
/* Clamped-cosine lobe m (at the normal n, frame t, b) times light lobe j: false when the
 * scene fit left the pair out; else the pair's weight w = mu * c_m * amp * int(hemisphere),
 * its f_h slope k and (withTheta) the SSDF's angle theta at the product lobe's axis, so the pair
 * adds w * fh_hat_slope(theta, k) to R_d.  Everything but theta depends on n alone. */
/* the cosine lobes' frame: the surface's (n, t, b), or a normal map's at this pixel (the
 * SSDF stays in the surface's frame: visibility is the geometry's); lobeMapped: the
 * latter, each pair then takes Cycles' terminator factor (texture.glsl
 * bump_shadowing) at its product lobe's axis, lobeSmooth the surface's normal */
vec3 lobeN, lobeT, lobeB;
bool lobeMapped = false;
vec3 lobeSmooth = vec3(0.0, 0.0, 1.0);

bool diffuse_pair(int m, int j, vec3 n, vec3 t, vec3 b, vec4 W[16], bool withTheta,
                  out float theta, out vec3 w, out float k)
{
  vec3 mu = texelFetch(lightTex, ivec2(1 + m, j), 0).rgb;   /* this cosine lobe's amplitude */
  theta = 0.0;
  w = vec3(0.0);
  k = 1.0;
  if (mu.r == 0.0 && mu.g == 0.0 && mu.b == 0.0) {
    return false;
  }
  vec4 cl = texelFetch(paramTex, ivec2(COSINE_TEXEL + m, 0), 0);
  vec3 cw = cl.x * lobeT + cl.y * lobeB + cl.z * lobeN;
  vec4 al = texelFetch(lightTex, ivec2(0, j), 0);
  vec3 axis = al.xyz * envRot;                 /* R^T a: texture -> world */
  vec3 p;
  float lam;
  float amp = sg_product(cw, cosLambda, axis, al.w, p, lam);
  vec3 local = vec3(dot(p, t), dot(p, b), dot(p, n));
  theta = withTheta ? ssdf_value(local, W) : 0.0;
  w = mu * (cl.w * amp * sg_hemisphere_integral(lam)) *
      (lobeMapped ? bump_shadowing(lobeSmooth, lobeN, p) : 1.0);
  k = fh_slope(lam);
  return true;
}

/* the point's own PCA weights (1, w_1..w_K) */
void point_weights(float point, out vec4 W[16])
{
  for (int l = 0; l < coeffTexels; l++) {
    W[l] = coeff_fetch(point, l);
  }
}
