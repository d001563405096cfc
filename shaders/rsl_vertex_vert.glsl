/* RSL per-vertex pass (Xu et al. 2006, §5.2): a full-screen quad over the point texture. */
void main()
{
  gl_Position = vec4(ndc, 0.0, 1.0);
}
