/* Full-screen quad at the far plane (drawn after the surfaces, depth test less-or-equal:
 * only uncovered samples); the fragment stage turns each pixel into a world direction. */
void main()
{
  vNdc = ndc;
  gl_Position = vec4(ndc, 1.0, 1.0);
}
