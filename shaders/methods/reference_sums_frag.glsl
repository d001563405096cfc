/* REFERENCE's glossy sum per shading point (Inger, Farbman, Lischinski 2013, §3, eq. 1), one
 * texel per point (addon/methods/reference/gpu.py): the GLSL twin of
 * core.methods.reference.shading.specular_radiance,
 *
 *   B_s(x, o) = sum_k  L_k dw_k V(x, w_k) f_s(w_k, o) max(0, n.w_k)
 *
 * over the cubemap texels the point sees (its visibility bits), with f_s the glossy lobes of
 * core.shading.brdf.specular_terms: D G2 / (4 cos_o) from dot products, each lobe's Fresnel
 * (lib/microfacet.glsl lobe_fresnel), times its per-point weight (lobe weight and
 * multiscatter factor at the point's cos_o, computed on the CPU).  With IRRADIANCE: the
 * diffuse sum of core.methods.reference.shading.diffuse_irradiance instead,
 * E(x) = sum_k L_k dw_k V(x, w_k) max(0, n.w_k) with w_k the texel's mean direction vector
 * (its mean cosine), no material.
 *
 * Textures (texelFetch only):
 *   pointData RGBA32F  rows of `width` (points by 4x4 blocks: point_of), four blocks of `rows`:
 *                      [normal, material], [bent view,
 *                      cos_o], [weight of lobe 0, the point's index in the visibility bits
 *                      (the glossy sums shade the points a camera may see)], [weight of
 *                      lobe 1, -]
 *   visTex    RGBA32F  the stored visibility bits (addon/gpu/visibility.py: np.packbits, three
 *                      bytes per float as an exact integer, bit b of float q is cubemap
 *                      texel 24 q + 23 - b), `stride` texels per point, rows of ROW_TEXELS
 *   envData   RGBA32F  rows of `envWidth`, three blocks of `envRows`: [unit direction, -],
 *                      [radiance times solid angle, -], [mean direction vector, -]
 *   matData   RGBA32F  row m per material: (alpha, distribution 0 Beckmann / 1 GGX, lobes,
 *                      -), then per lobe j at 1 + 3 j: (kind, eta, -, -), (f0, -), (B, -)
 */

/* texel i of a row-major block of `width` texels starting at row `row0`; `width` a power of
 * two (ENV_WIDTH): a mask and a shift, where an integer division per texel costs a
 * software rasterizer a scalar division per lane */
vec4 at(sampler2D tex, int i, int width, int row0)
{
  return texelFetch(tex, ivec2(i & (width - 1), row0 + (i >> findMSB(width))), 0);
}

/* the point a pixel holds: points 16 b .. 16 b + 15 fill the b-th 4x4 block of pixels row by
 * row (addon/methods/reference/gpu.py tiled_pixels), so a block's lanes shade neighbours */
int point_of(ivec2 q)
{
  ivec2 block = q >> 2;
  return 16 * (block.y * (width >> 2) + block.x) + 4 * (q.y & 3) + (q.x & 3);
}

void main()
{
  /* this draw's rows start at row firstRow of the points (drawn a block of rows at a time) */
  ivec2 q = ivec2(gl_FragCoord.xy) + ivec2(0, firstRow);
  int p = point_of(q);
  if (p >= pointCount) {
    fragColor = vec4(0.0);
    return;
  }
  vec4 nm = texelFetch(pointData, q, 0);
  vec3 n = nm.xyz;
#ifndef IRRADIANCE
  vec4 vc = texelFetch(pointData, q + ivec2(0, rows), 0);
  vec4 w0i = texelFetch(pointData, q + ivec2(0, 2 * rows), 0);
  vec3 w0 = w0i.rgb;
  vec3 w1 = texelFetch(pointData, q + ivec2(0, 3 * rows), 0).rgb;
  int m = int(nm.w + 0.5);
  vec4 head = texelFetch(matData, ivec2(0, m), 0);
  int lobes = SIG_COUNT(int(head.z + 0.5));
  if (lobes == 0) {
    fragColor = vec4(0.0);
    return;
  }
  vec3 o = vc.xyz;
  float cos_o = vc.w;
  float a = head.x;
  int dist = SIG_DIST(int(head.y + 0.5));
  float lam_o = smith_lambda(dist, a, cos_o);
  vec4 k0 = texelFetch(matData, ivec2(1, m), 0);
  vec3 f00 = texelFetch(matData, ivec2(2, m), 0).rgb;
  vec3 B0 = texelFetch(matData, ivec2(3, m), 0).rgb;
  vec4 k1 = texelFetch(matData, ivec2(4, m), 0);
  vec3 f01 = texelFetch(matData, ivec2(5, m), 0).rgb;
  vec3 B1 = texelFetch(matData, ivec2(6, m), 0).rgb;
#endif
#ifdef IRRADIANCE
  int first = p * stride;
#else
  int first = int(w0i.w + 0.5) * stride;       /* the point's row of the visibility bits */
#endif
  vec3 sum = vec3(0.0);
  for (int j = 0; j < stride; j++) {
    vec4 chunk = texelFetch(visTex, row_texel(first + j), 0);
    for (int c = 0; c < 4; c++) {
      uint bits = uint(chunk[c]);       /* exact integers below 2^24 */
      while (bits != 0u) {
        int b = findLSB(bits);
        bits &= bits - 1u;
        int k = 24 * (4 * j + c) + 23 - b;
        vec3 Ldw = at(envData, k, envWidth, envRows).rgb;
#ifdef IRRADIANCE
        sum += max(dot(n, at(envData, k, envWidth, 2 * envRows).xyz), 0.0) * Ldw;
#else
        vec3 i = at(envData, k, envWidth, 0).xyz;
        float cos_i = dot(n, i);
        float dot_io = dot(o, i);
        float len2 = max(2.0 + 2.0 * dot_io, 0.0);
        if (cos_i <= 0.0 || len2 <= HALF_LEN2_FLOOR) {
          continue;
        }
        float cos_h = clamp((cos_i + cos_o) * inversesqrt(len2), -1.0, 1.0);
        float lobe = ndf(dist, a, cos_h) /
                     (4.0 * cos_o * (1.0 + smith_lambda(dist, a, cos_i) + lam_o));
        float h_i = sqrt(clamp(0.5 * (1.0 + dot_io), 0.0, 1.0));
        vec3 f = w0 * lobe_fresnel(SIG_KIND0(int(k0.x + 0.5)), f00, B0, k0.y, h_i);
        if (lobes > 1) {
          f += w1 * lobe_fresnel(SIG_KIND1(int(k1.x + 0.5)), f01, B1, k1.y, h_i);
        }
        sum += lobe * f * Ldw;
#endif
      }
    }
  }
  fragColor = vec4(sum, 1.0);
}
