/* Full-screen quad; the fragment stage turns each pixel into a world direction. */
void main()
{
  vNdc = ndc;
  gl_Position = vec4(ndc, 0.0, 1.0);
}
