/* Blender's Image Texture node per pixel (GLSL twin of core/scene/textures.py sample): texel
 * centres at ((i + 0.5) / W, (j + 0.5) / H), row 0 at v = 0; interpolation 0 Closest,
 * 1 Linear, 2 Cubic (uniform B-spline); extension 0 Repeat, 1 Extend, 2 Clip, 3 Mirror.
 * texInfo = (interpolation, extension, source: -1 none / 0 image / 1 attribute, mix mode);
 * texMap0/1 = the Mapping node's 2D rows; mixColor = (constant colour, factor). */

int tex_wrap(int i, int n, int ext)
{
  if (ext == 0) {
    return floor_div(i, n).y;          /* common.glsl: no integer remainder */
  }
  if (ext == 3) {
    int m = floor_div(i, 2 * n).y;
    return m < n ? m : 2 * n - 1 - m;
  }
  return clamp(i, 0, n - 1);
}

vec4 tex_fetch(sampler2D img, int x, int y, ivec2 size, int ext)
{
  return texelFetch(img, ivec2(tex_wrap(x, size.x, ext), tex_wrap(y, size.y, ext)), 0);
}

vec4 bspline(float t)
{
  float t2 = t * t, t3 = t2 * t;
  return vec4((1.0 - t) * (1.0 - t) * (1.0 - t), 3.0 * t3 - 6.0 * t2 + 4.0,
              -3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0, t3) / 6.0;
}

vec4 image_texture(sampler2D img, vec2 uv, vec4 info, vec3 map0, vec3 map1)
{
  vec2 st = vec2(dot(map0, vec3(uv, 1.0)), dot(map1, vec3(uv, 1.0)));
  ivec2 size = textureSize(img, 0);
  int interp = int(info.x), ext = int(info.y);
  if (ext == 2 && (st.x < 0.0 || st.x > 1.0 || st.y < 0.0 || st.y > 1.0)) {
    return vec4(0.0);
  }
  vec2 p = st * vec2(size) - 0.5;
  /* a NaN or huge coordinate must not index outside the texture: clamp first */
  p = clamp(p, vec2(-1e6), vec2(1e6));
  if (interp == 0) {
    return tex_fetch(img, int(floor(p.x + 0.5)), int(floor(p.y + 0.5)), size, ext);
  }
  ivec2 i0 = ivec2(floor(p));
  vec2 f = p - vec2(i0);
  if (interp == 2) {
    vec4 wx = bspline(f.x), wy = bspline(f.y);
    vec4 sum = vec4(0.0);
    for (int j = 0; j < 4; j++) {
      for (int i = 0; i < 4; i++) {
        sum += wx[i] * wy[j] * tex_fetch(img, i0.x - 1 + i, i0.y - 1 + j, size, ext);
      }
    }
    return sum;
  }
  vec4 a = mix(tex_fetch(img, i0.x, i0.y, size, ext), tex_fetch(img, i0.x + 1, i0.y, size, ext),
               f.x);
  vec4 b = mix(tex_fetch(img, i0.x, i0.y + 1, size, ext),
               tex_fetch(img, i0.x + 1, i0.y + 1, size, ext), f.x);
  return mix(a, b, f.y);
}

/* core.scene.textures.ColorSource.combine: mode 0 none, 1 / 2 Mix / Multiply with the source as
 * the node's first input, 3 / 4 the same with the source second */
vec3 combine_colour(vec3 c, float mode_f, vec4 mixColor)
{
  int mode = int(mode_f + 0.5);
  if (mode == 0) {
    return c;
  }
  bool first = mode <= 2;
  vec3 a = first ? c : mixColor.rgb;
  vec3 b = first ? mixColor.rgb : c;
  float f = mixColor.a;
  return (mode == 2 || mode == 4) ? a * (1.0 - f + f * b) : mix(a, b, f);
}

/* a scalar input's value (Roughness, Metallic, ...): its colour as a float
 * (core.scene.textures.LUMINANCE), clamped to [0, 1] */
float scalar_input(vec3 c)
{
  return clamp(dot(c, LUMINANCE), 0.0, 1.0);
}

/* the colour of a textured input at this pixel (texInfo.z: 0 image at uv, 1 attribute) */
vec3 input_colour(sampler2D img, vec2 uv, vec4 attr, vec4 info, vec3 map0, vec3 map1,
                  vec4 mixColor)
{
  vec3 c = info.z < 0.5 ? image_texture(img, uv, info, map0, map1).rgb : attr.rgb;
  return max(combine_colour(c, info.w, mixColor), vec3(0.0));
}

/* core.scene.textures.perturbed_normals: the Normal Map (kind 1, tangent space) or Bump (kind 2)
 * node's normal at this pixel.  N, T: the interpolated (unnormalised) normal and tangent,
 * sgn the bitangent sign; nmap = (kind, strength, distance, -); info, map0/1, mixColor the
 * image's texture.glsl parameters.  The bump's height derivative: central differences one
 * texel each way in UV; its surface gradient from the screen derivatives of P and uv (on a
 * triangle exactly core.scene.textures.surface_gradient with its edges). */
float bump_height(sampler2D img, vec2 uv, vec4 info, vec3 map0, vec3 map1, vec4 mixColor)
{
  vec3 c = combine_colour(image_texture(img, uv, info, map0, map1).rgb, info.w, mixColor);
  return dot(c, LUMINANCE);
}

vec3 mapped_normal(sampler2D img, vec2 uv, vec3 P, vec3 N, vec3 T, float sgn, vec4 nmap,
                   vec4 info, vec3 map0, vec3 map1, vec4 mixColor)
{
  int kind = int(nmap.x + 0.5);
  vec3 Nu = normalize(N);
  if (kind == 0) {
    return Nu;
  }
  float strength = max(nmap.y, 0.0);
  vec3 n;
  if (kind == 1) {
    vec3 x = 2.0 * combine_colour(image_texture(img, uv, info, map0, map1).rgb, info.w,
                                  mixColor) - 1.0;
    n = x.x * T + x.y * (sgn * cross(N, T)) + x.z * N;
    n = dot(n, n) > 1e-30 ? normalize(n) : Nu;
    if (strength != 1.0) {
      n = Nu + (n - Nu) * strength;
      n = dot(n, n) > 1e-30 ? normalize(n) : Nu;
    }
    return n;
  }
  ivec2 size = textureSize(img, 0);
  vec2 step = 1.0 / max(vec2(length(vec2(map0.x, map1.x) * vec2(size)),
                             length(vec2(map0.y, map1.y) * vec2(size))), vec2(1e-12));
  vec2 dh = vec2(bump_height(img, uv + vec2(step.x, 0.0), info, map0, map1, mixColor) -
                 bump_height(img, uv - vec2(step.x, 0.0), info, map0, map1, mixColor),
                 bump_height(img, uv + vec2(0.0, step.y), info, map0, map1, mixColor) -
                 bump_height(img, uv - vec2(0.0, step.y), info, map0, map1, mixColor)) /
            (2.0 * step);
  vec3 dp1 = dFdx(P), dp2 = dFdy(P);
  vec2 duv1 = dFdx(uv), duv2 = dFdy(uv);
  vec3 r1 = cross(dp2, Nu), r2 = cross(Nu, dp1);
  float det = dot(dp1, r1);
  vec3 g = abs(det) > 1e-30 ? (dot(dh, duv1) * r1 + dot(dh, duv2) * r2) / det : vec3(0.0);
  n = Nu - nmap.z * g;
  n = dot(n, n) > 1e-30 ? normalize(n) : Nu;
  n = strength * n + (1.0 - strength) * Nu;
  return dot(n, n) > 1e-30 ? normalize(n) : Nu;
}

/* core.scene.textures.bump_shadowing: Cycles' terminator factor on a diffuse closure whose
 * normal n is not the smooth normal ns (Conty Estevez et al. 2019): GGX's Smith G1 at
 * |ns.i| with alpha^2 = min(tan^2 d / 8, 1), d the angle between ns and n */
float bump_shadowing(vec3 ns, vec3 n, vec3 i)
{
  if (n == ns) {
    return 1.0;
  }
  float cos_si = dot(ns, i), cos_sn = dot(ns, n);
  if (cos_si * cos_sn * dot(n, i) < 0.0) {
    return 0.0;                                /* i and n on different sides of ns */
  }
  float cos_i = abs(cos_si), cos_d = abs(cos_sn);
  if (cos_d >= 1.0 || cos_i >= 1.0) {
    return 1.0;
  }
  if (cos_i < 1e-6) {
    return 0.0;
  }
  float a2 = clamp(0.125 * (1.0 / (cos_d * cos_d) - 1.0), 0.0, 1.0);
  return 2.0 / (1.0 + sqrt(1.0 + a2 * (1.0 / (cos_i * cos_i) - 1.0)));
}

/* core.scene.textures.valid_reflection_normal: Cycles' bump map correction of a mapped normal n
 * (unit ng, view o) */
vec3 valid_reflection_normal(vec3 ng, vec3 o, vec3 n)
{
  vec3 r = 2.0 * dot(n, o) * n - o;
  float iz = dot(o, ng);
  float t = min(0.9 * iz, 0.01);
  if (dot(ng, r) >= t) {
    return n;
  }
  vec3 x = n - dot(n, ng) * ng;
  x = dot(x, x) > 1e-30 ? normalize(x) : n;
  float ix = dot(o, x);
  float a = ix * ix + iz * iz;
  float b = 2.0 * (a + iz * t);
  float c = (t + iz) * (t + iz);
  float root = sqrt(max(b * b - 4.0 * a * c, 0.0));
  float nz2 = ix < 0.0 ? 0.25 * (b + root) / a : 0.25 * (b - root) / a;
  return sqrt(max(1.0 - nz2, 0.0)) * x + sqrt(max(nz2, 0.0)) * ng;
}
