/* A full-screen quad or triangle, no varyings: the passes that write one texel per fragment
 * (RSL's per-vertex pass, SSDF_SG's pair pass) read gl_FragCoord. */
void main()
{
  gl_Position = vec4(ndc, 0.0, 1.0);
}
