/* Microfacet BRDF pieces (after constants.glsl): Cycles' Beckmann/GGX NDFs and Smith Lambda,
 * the dielectric Fresnel, the Fresnel kinds of core.shading.brdf.sharp_lobes, NDF sampling.
 * GLSL twin of core/shading/microfacet.py and core/shading/brdf.py, read by the per-pixel
 * passes (sharp_lobe_frag.glsl, lights_frag.glsl) and by sg.glsl's SG BRDFs. */

/* ---------------------------------------------------------------- microfacet terms */

/* what a draw's materials share is compiled in (core.shading.microfacet.lobe_signature), else
 * read at run time: llvmpipe runs every side of a branch under a mask */
#ifdef LOBE_DIST
#define SIG_DIST(d) LOBE_DIST
#else
#define SIG_DIST(d) (d)
#endif
#ifdef LOBE_COUNT
#define SIG_COUNT(n) LOBE_COUNT
#else
#define SIG_COUNT(n) (n)
#endif
#ifdef LOBE_KIND0
#define SIG_KIND0(k) LOBE_KIND0
#else
#define SIG_KIND0(k) (k)
#endif
#ifdef LOBE_KIND1
#define SIG_KIND1(k) LOBE_KIND1
#else
#define SIG_KIND1(k) (k)
#endif

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

/* a half vector drawn with density D(h) (n.h) from uniform u in [0, 1)^2 */
vec3 sample_ndf(int dist, float a, vec2 u, vec3 n, vec3 tx, vec3 ty)
{
  float tan2 = dist == 0 ? -a * a * log(1.0 - u.x) : a * a * u.x / (1.0 - u.x);
  float ch = inversesqrt(1.0 + tan2);
  float sh = sqrt(max(1.0 - ch * ch, 0.0));
  float phi = 2.0 * PI * u.y;
  return normalize(tx * (sh * cos(phi)) + ty * (sh * sin(phi)) + n * ch);
}

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

