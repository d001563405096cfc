/* A sun-like source's shadow map (addon/gpu/lights.py): the casters' depth seen from the
 * source, one orthographic tile of the atlas. */
void main()
{
  gl_Position = viewProjection * vec4(pos, 1.0);
}
