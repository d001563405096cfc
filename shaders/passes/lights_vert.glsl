/* Compact light sources per pixel (addon/gpu/lights.py): per-corner position and normal, and
 * the UVs or colour attribute of a textured colour input, the tangent and bitangent sign of
 * a normal map. */
void main()
{
  vPos = pos;
  vNrm = nrm;
  vUv = uv;
  vAttr = attr;
  vTng = tng;
  gl_Position = viewProjection * vec4(pos, 1.0);
}
