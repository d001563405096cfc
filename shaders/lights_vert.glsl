/* Compact light sources per pixel (addon/lights.py): per-corner position and normal. */
void main()
{
  vPos = pos;
  vNrm = nrm;
  gl_Position = viewProjection * vec4(pos, 1.0);
}
