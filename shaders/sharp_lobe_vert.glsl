/* Per-pixel glossy lobes too narrow for the cubemap (addon/sharp.py): per-corner
 * position and normal, the triangle's three shading points and barycentric weights, so
 * the fragment can read each point's stored visibility at its own directions. */
void main()
{
  vPos = pos;
  vNrm = nrm;
  vBary = bary;
  vTri = triPoints;
  gl_Position = viewProjection * vec4(pos, 1.0);
}
