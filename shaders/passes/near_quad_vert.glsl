/* A full-screen quad at the near plane (depth 0): adaptive anti-aliasing's mask and fill
 * (adaptive_frag.glsl), which every surface lies behind. */
void main()
{
  gl_Position = vec4(ndc, -1.0, 1.0);
}
