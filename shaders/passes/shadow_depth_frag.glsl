/* Depth only: the colour is not read. */
void main()
{
  fragColor = vec4(0.0);
}
