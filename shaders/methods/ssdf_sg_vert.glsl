/* SSDF_SG (Wang et al. 2009): per-corner position/normal, the triangle's three shading
 * points (flat) and barycentric weights, so the fragment shader interpolates the
 * PCA coefficients (eq. 24) of the three points it lies between (section 7). */
void main()
{
  vPos = pos;
  vNrm = nrm;
  vBary = bary;
  vTri = triPoints;
  vUv = uv;
  vAttr = attr;
  vTng = tng;
#ifdef FLAT_PAIRS
  vFlat = triFlat;   /* the three points' rows in the pair table */
#endif
  gl_Position = viewProjection * vec4(pos, 1.0);
}
