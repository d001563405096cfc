/* RSL per-vertex shading (Xu et al. 2006, Fig. 8, eq. 5): one texel per shading point.
 *
 * For every rotatable square light: its centre in the vertex frame (t, b, n) gives the
 * square in the disk map p = sqrt(1 - cos) (sin f, cos f); the visibility average comes
 * from the vertex's distance table (eq. 9) or visibility SAT, the cosine and BRDF
 * averages from the summed-area tables (4 look-ups each, linear between view nodes)
 * in the frame whose x axis is the projected view.  Output: diffuse and per-term
 * glossy sums weighted by per-vertex view-dependent weights (Fresnel/layering).
 *
 * Textures (texelFetch only, so the sums equal the numpy evaluator's):
 *   pointData  RGBA32F  rows of `width`: [normal, 0] at (x, y), view dir at (x, y + rows),
 *                       at (x, y + 2 rows) the point's visibility table index, the first
 *                       block of its material's tables and its material's term count
 *   weights    RGBA32F  (width, rows * (terms + 1)): diffuse weight, then term weights
 *   lights     RGBA32F  (lightCount, 2): [centre, half side], [energy, 0]
 *   visTable   R16F/R32F per-vertex N x N (VDT) or (N+1) x (N+1) (SAT) tables, each
 *                       visTile² texels in row-major order from texel index * visTile²
 *   brdfTables RGBA32F  (N+2) x (N+1) blocks, `blockCols` to a row of blocks: per material
 *                       its cosine table, then terms x view nodes (every material of the
 *                       pass, one after another); column N+1, row 0 holds the block's
 *                       offset (mean per area)
 */

float table_texel(bool vis, ivec2 origin, int x, int y)
{
  /* brdfTables: a block at `origin`; visTable: the point's table from texel origin.x */
  if (vis) {
    int w = textureSize(visTable, 0).x;
    return texelFetch(visTable, floor_div(origin.x + y * visTile + x, w).yx, 0).r;
  }
  return texelFetch(brdfTables, origin + ivec2(x, y), 0).r;
}

float sat_at(bool vis, ivec2 origin, int n, float x, float y)
{
  /* bilinear sample of an (n+1) x (n+1) corner table at grid coordinates (x, y) */
  x = clamp(x, 0.0, float(n));
  y = clamp(y, 0.0, float(n));
  /* integer indices clamped too: a NaN coordinate converts to any int, and a fetch
   * outside the texture is undefined (llvmpipe reads out of bounds) */
  int x0 = clamp(int(x), 0, n - 1);
  int y0 = clamp(int(y), 0, n - 1);
  float fx = x - float(x0);
  float fy = y - float(y0);
  float a = table_texel(vis, origin, x0, y0);
  float b = table_texel(vis, origin, x0 + 1, y0);
  float c = table_texel(vis, origin, x0, y0 + 1);
  float d = table_texel(vis, origin, x0 + 1, y0 + 1);
  float top = a * (1.0 - fx) + b * fx;
  float bot = c * (1.0 - fx) + d * fx;
  return top * (1.0 - fy) + bot * fy;
}

float box(bool vis, ivec2 origin, int n, vec2 p, float half_side)
{
  float k = 0.5 * float(n);
  float x0 = (p.x - half_side + 1.0) * k, x1 = (p.x + half_side + 1.0) * k;
  float y0 = (p.y - half_side + 1.0) * k, y1 = (p.y + half_side + 1.0) * k;
  return sat_at(vis, origin, n, x1, y1) - sat_at(vis, origin, n, x0, y1) -
         sat_at(vis, origin, n, x1, y0) + sat_at(vis, origin, n, x0, y0);
}

float clipped_area(vec2 p, float h)
{
  float wx = clamp(p.x + h, -1.0, 1.0) - clamp(p.x - h, -1.0, 1.0);
  float wy = clamp(p.y + h, -1.0, 1.0) - clamp(p.y - h, -1.0, 1.0);
  return wx * wy;
}

float table_box(int block, vec2 p, float h)
{
  /* average of block's function over the square, offset added back */
  ivec2 origin = floor_div(block, blockCols).yx * ivec2(brdfRes + 2, brdfRes + 1);
  float off = texelFetch(brdfTables, origin + ivec2(brdfRes + 1, 0), 0).r;
  return (box(false, origin, brdfRes, p, h) + off * clipped_area(p, h)) / (4.0 * h * h);
}

vec2 disk(vec3 l)
{
  float r = sqrt(max(0.0, 1.0 - clamp(l.z, -1.0, 1.0)));
  float rho = length(l.xy);
  return rho > 0.0 ? r * vec2(l.y, l.x) / rho : vec2(0.0, r);
}

float visibility(int base, vec2 p, float h)
{
  ivec2 origin = ivec2(base, 0);
  if (visMode == 0) { /* VDT, eq. 9 */
    int n = visRes;
    float k = 0.5 * float(n);
    float x = clamp((p.x + 1.0) * k - 0.5, 0.0, float(n - 1));
    float y = clamp((p.y + 1.0) * k - 0.5, 0.0, float(n - 1));
    int x0 = clamp(int(x), 0, n - 2);
    int y0 = clamp(int(y), 0, n - 2);
    float fx = x - float(x0), fy = y - float(y0);
    float a = table_texel(true, origin, x0, y0);
    float b = table_texel(true, origin, x0 + 1, y0);
    float c = table_texel(true, origin, x0, y0 + 1);
    float d = table_texel(true, origin, x0 + 1, y0 + 1);
    float D = (a * (1.0 - fx) + b * fx) * (1.0 - fy) + (c * (1.0 - fx) + d * fx) * fy;
    return clamp((h + D) / (2.0 * h), 0.0, 1.0);
  }
  /* SAT: the average over the part of the square inside the table (as core.methods.rsl.shading) */
  float area = clipped_area(p, h);
  return area > 1e-12 ? box(true, origin, visRes, p, h) / area : 1.0;
}

void main()
{
  ivec2 pix = ivec2(gl_FragCoord.xy);
  int index = pix.y * width + pix.x;
  if (index >= pointCount) {
    fragColor = vec4(0.0);
    return;
  }
  int rows = (pointCount + width - 1) / width;
  vec3 n = texelFetch(pointData, pix, 0).xyz;
  vec3 v = texelFetch(pointData, pix + ivec2(0, rows), 0).xyz;
  vec3 t, b;
  tangent_frame(n, t, b);
  /* view frame: x axis = view projected on the tangent plane */
  float cos_o = dot(n, v);
  vec3 tp = v - cos_o * n;
  float ln = length(tp);
  tp = ln > 1e-9 ? tp / ln : t;
  vec3 bp = cross(n, tp);
  float theta = acos(clamp(cos_o, 0.0, 1.0));
  float node = clamp(theta / viewStep, 0.0, float(viewNodes - 1));
  int j0 = min(int(node), viewNodes - 2);
  float fj = node - float(j0);

  vec4 ids = texelFetch(pointData, pix + ivec2(0, 2 * rows), 0);
  int vis_index = int(ids.x + 0.5);
  int first = int(ids.y + 0.5);             /* the material's cosine table */
  int terms = min(int(ids.z + 0.5), termCount);
  int base = vis_index * visTile * visTile;

  vec3 diffuse = vec3(0.0);
  vec3 glossy[MAX_TERMS];
  for (int k = 0; k < MAX_TERMS; k++) {
    glossy[k] = vec3(0.0);
  }
  for (int i = 0; i < lightCount; i++) {
    vec4 cl = texelFetch(lights, ivec2(i, 0), 0);
    vec3 E = texelFetch(lights, ivec2(i, 1), 0).rgb;
    float h = cl.w;
    vec2 p = disk(vec3(dot(cl.xyz, t), dot(cl.xyz, b), dot(cl.xyz, n)));
    float V = visibility(base, p, h);
    if (V <= 0.0) {
      continue;
    }
    diffuse += E * (V * table_box(first, p, h));
    if (terms > 0) {
      vec2 q = disk(vec3(dot(cl.xyz, tp), dot(cl.xyz, bp), dot(cl.xyz, n)));
      for (int k = 0; k < terms; k++) {
        int blk = first + 1 + k * viewNodes + j0;
        float g = (1.0 - fj) * table_box(blk, q, h) + fj * table_box(blk + 1, q, h);
        glossy[k] += E * (V * g);
      }
    }
  }
  vec3 color = diffuse * texelFetch(weights, pix, 0).rgb;
  for (int k = 0; k < terms; k++) {
    color += glossy[k] * texelFetch(weights, pix + ivec2(0, (k + 1) * rows), 0).rgb;
  }
  fragColor = vec4(color, 1.0);
}
