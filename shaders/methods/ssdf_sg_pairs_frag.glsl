/* SSDF_SG pair pass (flat triangles, see ssdf_sg_frag.glsl's FLAT_PAIRS): one fragment per
 * texel of the pair table, row-major in rows of ROW_TEXELS texels, stride = T + P texels per flat
 * point for P = cosine lobes x light lobes pairs and T = ceil(P / 4):
 *   texel c < T       : the SSDF angle theta of pairs 4c..4c+3 (diffuse_pair),
 *   texel T + p       : (w, k) of pair p = m * lightCount + j.
 * flatTex texel q = (normal of flat point q, its point index). */
void main()
{
  read_parameters();
  int pairs = cosLobes * lightCount;
  int thetaTexels = (pairs + 3) / 4;
  int stride = thetaTexels + pairs;
  int idx = int(gl_FragCoord.y) * ROW_TEXELS + int(gl_FragCoord.x);
  int q = idx / stride;
  int c = idx - q * stride;
  if (q >= flatCount) {
    fragColor = vec4(0.0);
    return;
  }
  vec4 fp = texelFetch(flatTex, row_texel(q), 0);
  vec3 n = normalize(fp.xyz);
  vec3 t, b;
  ssdf_frame(n, t, b);
  lobeN = n;
  lobeT = t;
  lobeB = b;
  vec4 W[16];
  point_weights(fp.w, W);
  float theta, k;
  vec3 w;
  if (c < thetaTexels) {
    vec4 th = vec4(0.0);
    for (int i = 0; i < 4 && 4 * c + i < pairs; i++) {
      int p = 4 * c + i;
      diffuse_pair(p / lightCount, p - (p / lightCount) * lightCount, n, t, b, W, true, theta, w,
                   k);
      th[i] = theta;
    }
    fragColor = th;
  }
  else {
    int p = c - thetaTexels;
    diffuse_pair(p / lightCount, p - (p / lightCount) * lightCount, n, t, b, W, false, theta, w,
                 k);
    fragColor = vec4(w, k);
  }
}
