/* Compact light sources per pixel (addon/lights.py): per-corner position and normal, and
 * the UVs or colour attribute of a textured colour input. */
void main()
{
  vPos = pos;
  vNrm = nrm;
  vUv = uv;
  vAttr = attr;
  gl_Position = viewProjection * vec4(pos, 1.0);
}
