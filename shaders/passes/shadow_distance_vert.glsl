/* A local lamp's shadow faces (addon/gpu/lights.py): six 90-degree views around the lamp,
 * each fragment's world position passed on. */
void main()
{
  vPos = pos;
  gl_Position = viewProjection * vec4(pos, 1.0);
}
