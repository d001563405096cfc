/* Per-vertex outgoing radiance, computed on the CPU by the active method,
 * interpolated across triangles (Gouraud, in linear radiance). */
void main()
{
  vRadiance = radiance;
  gl_Position = viewProjection * vec4(pos, 1.0);
}
