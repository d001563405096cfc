/* Per-pixel main pass: kd R_d + R_s(o) of the fragment's material slot.  Built twice:
 * as is for every triangle, and with FLAT_PAIRS for flat ones (pairTex, vFlat). */
#ifdef FLAT_PAIRS
/* texel c of flat point q's row of the pair table (stride texels per point) */
vec4 pair_fetch(float q, int stride, int c)
{
  int idx = int(q + 0.5) * stride + c;
  return texelFetch(pairTex, row_texel(idx), 0);
}
#endif

/* textured input k of the slot (0 colour, 1 roughness, 2 metallic, 3 specular IOR level)
 * at this pixel; false when it has none */
bool slot_input(sampler2D img, int k, out vec3 c)
{
  int i = INPUT_TEXEL + 4 * k;
  vec4 info = texelFetch(paramTex, ivec2(i, 0), 0);
  c = vec3(1.0);
  if (info.z < -0.5) {
    return false;
  }
  c = input_colour(img, vUv, vAttr, info, texelFetch(paramTex, ivec2(i + 1, 0), 0).xyz,
                   texelFetch(paramTex, ivec2(i + 2, 0), 0).xyz,
                   texelFetch(paramTex, ivec2(i + 3, 0), 0));
  return true;
}

vec4 table_texel(int i, int j, int k)
{
  return texelFetch(paramTex, ivec2(i * ENTRY_TEXELS + k, 1 + j), 0);
}

/* texel k of the table entry at fractional roughness node x and level node y */
vec4 table_entry(float x, float y, int nr, int nl, int k)
{
  int i0 = min(int(x), nr - 1), j0 = min(int(y), nl - 1);
  int i1 = min(i0 + 1, nr - 1), j1 = min(j0 + 1, nl - 1);
  float fx = x - float(i0), fy = y - float(j0);
  return mix(mix(table_texel(i0, j0, k), table_texel(i1, j0, k), fx),
             mix(table_texel(i0, j1, k), table_texel(i1, j1, k), fx), fy);
}

/* the GGX lobes' inputs at table position (x, y), metallic weight mw, base colour cf (the
 * second lobe as the first: lambda a^2, mu a^2; the corner terms bilinear as in apply_inputs) */
void ggx_inputs(float x, float y, int nr, int nl, float mw, vec3 cf)
{
  entryX = x;
  entryY = y;
  tableNr = nr;
  tableNl = nl;
  if (brdfModel != 3) {
    return;
  }
  vec4 e = table_entry(x, y, nr, nl, GGX_TEXEL);
  vec3 q[3];
  int k0 = GGX_TEXEL + 1 + GGX_E_NODES / 4;
  for (int j = 0; j < 3; j++) {
    vec3 lo = mix(table_entry(x, y, nr, nl, k0 + j).rgb, table_entry(x, y, nr, nl, k0 + 6 + j).rgb, mw);
    vec3 hi = mix(table_entry(x, y, nr, nl, k0 + 3 + j).rgb, table_entry(x, y, nr, nl, k0 + 9 + j).rgb, mw);
    q[j] = lo + (hi - lo) * cf;
  }
  fresAm = q[0];
  /* Cycles' F_ms = F_ss E_avg / (1 - F_ss (1 - E_avg)) of the pixel's F_ss (0: no multiscatter) */
  float ea = e.z;
  fmsMain = e.w > 0.5 ? q[1] * ea / max(1.0 - q[1] * (1.0 - ea), vec3(1e-12)) : vec3(0.0);
  fmsMetal = e.w > 0.5 ? q[2] * ea / max(1.0 - q[2] * (1.0 - ea), vec3(1e-12)) : vec3(0.0);
}

/* a curve of the pixel's table entry at the GGX_E_NODES mu nodes from texel `first` (four a texel),
 * linear in mu between them: Cycles' GGX albedo E(r, mu) (as core.shading.brdf_tables.ggx_E), or
 * the Lambert base's view ratio (core.sg.brdf.diffuse_view_ratio) */
float entry_mu_curve(int first, float mu)
{
  float x = clamp(mu, 0.0, 1.0) * float(GGX_E_NODES - 1);
  int i = min(int(x), GGX_E_NODES - 1);
  int j = min(i + 1, GGX_E_NODES - 1);
  vec4 ti = table_entry(entryX, entryY, tableNr, tableNl, first + i / 4);
  vec4 tj = table_entry(entryX, entryY, tableNr, tableNl, first + j / 4);
  return mix(ti[i % 4], tj[j % 4], x - float(i));
}

/* Eq. 41 for the GGX model (core.sg.brdf.specular_lobes): the view slice as WARP_LOBES_MAX
 * fitted lobes, scaled together so the slice has Cycles' albedo E(r, n.o) against the
 * cosine mixture it is shaded with, in the glossy frame (nl, gt, gb: the bump-corrected
 * normal's), each with the Fresnel at the half vector of its product with the cosine,
 * times Cycles' multiscatter factor per layer */
vec3 ggx_specular(vec3 o, vec3 nl, vec3 gt, vec3 gb, vec3 t, vec3 b, vec3 n, vec4 W[16])
{
  float c = dot(o, nl);
  if (c <= 0.0) {
    return vec3(0.0);
  }
  /* the fitted lobes (core.sg.ndf.ggx_warp_correct): the mirror direction tilted in the
   * plane of nl and o, the plain warp's sharpness of the NDF's 2 / a^2 scaled, the shares
   * of the amplitude; the table's three texels a node linear between its WARP_MU_NODES n.o
   * nodes */
  float wx = clamp(c, 0.0, 1.0) * float(WARP_MU_NODES - 1);
  int wi = min(int(wx), WARP_MU_NODES - 2);
  float wf = wx - float(wi);
  vec4 q[3];
  for (int j = 0; j < 3; j++) {
    q[j] = mix(table_entry(entryX, entryY, tableNr, tableNl, WARP_TEXEL + 3 * wi + j),
               table_entry(entryX, entryY, tableNr, tableNl, WARP_TEXEL + 3 * wi + 3 + j), wf);
  }
  vec3 u = c * nl - o;
  float ul = length(u);
  u = ul > 1e-9 ? u / ul : gt;
  float el0 = acos(clamp(c, 0.0, 1.0));
  float a = max(roughness, SG_ALPHA_MIN);
  float lamW = min(2.0 / (a * a) / (4.0 * max(c, WARP_MU_MIN)), SG_LAMBDA_MAX);
  vec3 axes[WARP_LOBES_MAX];
  float lams[WARP_LOBES_MAX];
  float mus[WARP_LOBES_MAX];
  for (int k = 0; k < WARP_LOBES_MAX; k++) {
    axes[k] = cos(el0 + q[0][k]) * nl + sin(el0 + q[0][k]) * u;
    lams[k] = min(lamW * exp(q[1][k]), SG_LAMBDA_MAX);
    mus[k] = max(q[2][k], 0.0);
  }
  float E = entry_mu_curve(GGX_TEXEL + 1, max(c, COS_VIEW_MIN));
  /* E against the cosine mixture the lobes are shaded with, each product weighted by the
   * visibility factor of the open hemisphere over nl (its elevation), as a flat open
   * surface is drawn below (core.sg.brdf._ggx_normalisation) */
  float asg = 0.0;
  for (int m = 0; m < cosLobes; m++) {
    vec4 cl = texelFetch(paramTex, ivec2(COSINE_TEXEL + m, 0), 0);
    vec3 cw = cl.x * gt + cl.y * gb + cl.z * nl;
    for (int k = 0; k < WARP_LOBES_MAX; k++) {
      vec3 p;
      float lam;
      float amp = sg_product(cw, cosLambda, axes[k], lams[k], p, lam);
      float vis = fh_hat(asin(clamp(dot(p, nl), -1.0, 1.0)), lam);
      asg += mus[k] * cl.w * amp * sg_integral(lam) * vis;
    }
  }
  float norm = E / max(asg, 1e-30);
  float missing = (1.0 - max(E, 1e-6)) / max(E, 1e-6);
  vec3 kmain = 1.0 + missing * fmsMain;
  vec3 kmetal = 1.0 + missing * fmsMetal;
  vec3 color = vec3(0.0);
  for (int k = 0; k < WARP_LOBES_MAX; k++) {
    if (mus[k] <= 0.0) {
      continue;
    }
    vec3 h = normalize(normalize(lams[k] * axes[k] + CLAMPED_COSINE_LAMBDA * nl) + o);
    float cf = clamp(dot(h, o), 0.0, 1.0);
    float s5 = pow(1.0 - cf, 5.0);
    vec3 fres = fresA.rgb + fresBd.rgb * fresnel_dielectric(cf, ior) + fresBs.rgb * s5;
    vec3 metal = vec3(0.0);
    if (principled != 0) {
      fres = max(fres, vec3(0.0));
      metal = fresAm + fresBs.rgb * s5;
    }
    vec3 mu = mus[k] * norm * (fres * kmain + metal * (kmetal - kmain));
    for (int m = 0; m < cosLobes; m++) {
      vec4 cl = texelFetch(paramTex, ivec2(COSINE_TEXEL + m, 0), 0);
      vec3 cw = cl.x * gt + cl.y * gb + cl.z * nl;
      vec3 p;
      float lam;
      float amp = sg_product(cw, cosLambda, axes[k], lams[k], p, lam);
      color += cl.w * amp * mu * visible_lighting(p, lam, t, b, n, W) * envStrength;
    }
  }
  return color;
}

/* the slot's textured inputs at this pixel: the NDF lobe and eta from the table at the
 * pixel's roughness and level, kd and the Fresnel terms bilinear in (metallic, base
 * colour) between the table's corners (exact: they are bilinear in the two) */
void apply_inputs()
{
  vec4 t = texelFetch(paramTex, ivec2(TABLE_TEXEL, 0), 0);
  int nr = int(t.x + 0.5), nl = int(t.y + 0.5);
  vec3 c, v;
  bool coloured = slot_input(albedoTex, 0, c);
  float x = 0.0, y = 0.0, mw = 0.0;
  if (slot_input(roughTex, 1, v)) {
    float r = scalar_input(v);
    x = r * float(nr - 1);
    roughness = max(r * r, SG_ALPHA_MIN);
  }
  if (slot_input(metalTex, 2, v)) {
    mw = (scalar_input(v) - t.z) / max(t.w - t.z, 1e-6);
  }
  if (slot_input(levelTex, 3, v)) {
    y = scalar_input(v) * float(nl - 1);
  }
  ggx_inputs(x, y, nr, nl, mw, clamp(c, 0.0, 1.0));
  if (!coloured && x == 0.0 && y == 0.0 && mw == 0.0 && nr == 1 && nl == 1) {
    return;
  }
  if (nr > 1 || nl > 1) {
    vec4 e0 = table_entry(x, y, nr, nl, 0);
    float a2 = roughness * roughness;
    ndfLambda = max(e0.x / a2, SG_LAMBDA_MIN);
    ndfMu = e0.y / a2;
    ior = e0.z;
  }
  vec3 cf = clamp(c, 0.0, 1.0);
  vec3 q[4];
  for (int k = 0; k < 4; k++) {
    vec3 lo = mix(table_entry(x, y, nr, nl, 1 + k).rgb, table_entry(x, y, nr, nl, 9 + k).rgb, mw);
    vec3 hi = mix(table_entry(x, y, nr, nl, 5 + k).rgb, table_entry(x, y, nr, nl, 13 + k).rgb, mw);
    q[k] = lo + (hi - lo) * (k == 0 ? c : cf);
  }
  kd.rgb = q[0];
  fresA.rgb = q[1];
  fresBd.rgb = q[2];
  fresBs.rgb = q[3];
}

/* the glossy lobe's frame: lobeN's, or a mapped normal's after the bump map correction */
vec3 glossN, glossT, glossB;

/* a normal or bump map (NORMAL_TEXEL: kind, strength, distance; its image's texture.glsl
 * parameters after the cosine lobes): the cosine lobes' and the glossy lobe's frame at this
 * pixel (Wang et al. 2009 shade per pixel in the normal map's frame); as Cycles' Principled
 * BSDF, the diffuse lobes take the mapped normal as is (with the terminator factor), the
 * glossy lobe its bump map correction toward the surface normal n */
void mapped_frame(vec3 n, vec3 o)
{
  vec4 nmap = texelFetch(paramTex, ivec2(NORMAL_TEXEL, 0), 0);
  if (nmap.x < 0.5) {
    return;
  }
  int base = COSINE_TEXEL + cosLobes;
  vec3 m = mapped_normal(normalTex, vUv, vPos, vNrm, vTng.xyz, vTng.w, nmap,
                         texelFetch(paramTex, ivec2(base, 0), 0),
                         texelFetch(paramTex, ivec2(base + 1, 0), 0).xyz,
                         texelFetch(paramTex, ivec2(base + 2, 0), 0).xyz,
                         texelFetch(paramTex, ivec2(base + 3, 0), 0));
  lobeN = m;
  ssdf_frame(lobeN, lobeT, lobeB);
  lobeMapped = true;
  lobeSmooth = n;
  glossN = dot(n, o) > 0.0 ? valid_reflection_normal(n, o, m) : m;
  ssdf_frame(glossN, glossT, glossB);
}

void main()
{
  read_parameters();
  apply_inputs();
  vec3 n = normalize(vNrm);
  vec3 t, b;
  ssdf_frame(n, t, b);
  lobeN = n;
  lobeT = t;
  lobeB = b;
  glossN = n;
  glossT = t;
  glossB = b;
  vec3 view = view_direction(eye, vPos);
  mapped_frame(n, view);
  vec4 W[16];
  bool perPixelSSDF = glossy != 0;
#ifndef FLAT_PAIRS
  perPixelSSDF = true;
#endif
  for (int l = 0; perPixelSSDF && l < coeffTexels; l++) {
    W[l] = vBary.x * coeff_fetch(vTri.x, l) + vBary.y * coeff_fetch(vTri.y, l) +
           vBary.z * coeff_fetch(vTri.z, l);
  }
  /* eq. 39: every (clamped-cosine lobe, light lobe) product probes the SSDF at its axis */
  vec3 rd = vec3(0.0);
  /* a slot without a diffuse part (kd = 0: a pure Glossy BSDF) skips eq. 39 */
  bool diffuse = kd.r > 0.0 || kd.g > 0.0 || kd.b > 0.0;
#ifdef FLAT_PAIRS
  /* a flat triangle: n, t, b and so every pair's product lobe are the same at its three
   * points and inside it, and eq. 24 is linear in the weights, so the SSDF angle at a
   * pixel is the barycentric mix of the points' angles at the same axis: the pair pass
   * (ssdf_sg_pairs_frag.glsl) tabulated them per point with the weight and slope */
  int pairs = cosLobes * lightCount;
  int thetaTexels = (pairs + 3) / 4;
  int stride = thetaTexels + pairs;
  if (diffuse) {
    for (int c = 0; c < thetaTexels; c++) {
      vec4 th = vBary.x * pair_fetch(vFlat.x, stride, c) +
                vBary.y * pair_fetch(vFlat.y, stride, c) +
                vBary.z * pair_fetch(vFlat.z, stride, c);
      for (int i = 0; i < 4 && 4 * c + i < pairs; i++) {
        vec4 wk = pair_fetch(vFlat.x, stride, thetaTexels + 4 * c + i);
        rd += wk.rgb * fh_hat_slope(th[i], wk.w);
      }
    }
  }
#else
  for (int m = 0; diffuse && m < cosLobes; m++) {
    for (int j = 0; j < lightCount; j++) {
      float theta, k;
      vec3 w;
      if (diffuse_pair(m, j, n, t, b, W, true, theta, w, k)) {
        rd += w * fh_hat_slope(theta, k);
      }
    }
  }
#endif
  vec3 color = kd.rgb * entry_mu_curve(LAYER_TEXEL, dot(glossN, view)) * rd * envStrength;
  if (glossy != 0 && brdfModel == 3) {
    color += ggx_specular(view, glossN, glossT, glossB, t, b, n, W);
  }
  /* eq. 41 with the one-lobe isotropic NDF view slice (eq. 17-22) */
  else if (glossy != 0) {
    vec3 o = view;
    vec3 nl = glossN;
    float c = dot(o, nl);
    vec3 pw = 2.0 * c * nl - o;
    pw = pw / max(length(pw), 1e-30);
    float tau = max(4.0 * abs(c), 4.0 * SG_COS_MIN);
    float lam_w = min(ndfLambda / tau, SG_LAMBDA_MAX);
    float cos_i = dot(nl, pw);
    float cos_o = dot(nl, o);
    float m = m_factor(cos_i, cos_o, c) * (c > 0.0 ? 1.0 : 0.0);
    float cf = clamp(c, 0.0, 1.0);
    vec3 fres = fresA.rgb + fresBd.rgb * fresnel_dielectric(cf, ior) +
                fresBs.rgb * pow(1.0 - cf, 5.0);
    if (principled != 0) {
      fres = max(fres, vec3(0.0));
    }
    vec3 mu = ndfMu * m * fres;
    for (int k = 0; k < cosLobes; k++) {
      vec4 cl = texelFetch(paramTex, ivec2(COSINE_TEXEL + k, 0), 0);
      vec3 cw = cl.x * glossT + cl.y * glossB + cl.z * nl;
      vec3 p;
      float lam, amp;
      amp = sg_product(cw, cosLambda, pw, lam_w, p, lam);
      color += cl.w * amp * mu * visible_lighting(p, lam, t, b, n, W) * envStrength;
    }
  }
  if (other_copy(closedSide)) discard;
  /* a closed mesh's inner side (core.scene.mesh.closed_side) sees only itself: black, as in
   * Cycles; SG products can ring slightly below zero: clamped */
  fragColor = vec4(inner_side(closedSide) ? vec3(0.0) : max(color, vec3(0.0)), 1.0);
}
