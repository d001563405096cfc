/* Per-pixel glossy lobes too narrow for the cubemap (addon/gpu/sharp.py): per-corner
 * position and normal, the triangle's three shading points with their normals and
 * barycentric weights, so the fragment can read each point's stored visibility at its
 * own directions (and know which directions a point traced); the UVs of a textured
 * Roughness or normal map, the tangent and bitangent sign of a normal map. */
void main()
{
  vPos = pos;
  vNrm = nrm;
  vBary = bary;
  vUv = uv;
  vTng = tng;
  vTri = triPoints;
  vTriN0 = triN0;
  vTriN1 = triN1;
  vTriN2 = triN2;
  gl_Position = viewProjection * vec4(pos, 1.0);
}
