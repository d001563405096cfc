/* A local lamp's shadow faces (addon/gpu/lights.py): six 90-degree views around the lamp,
 * each fragment's world position passed on.  PLACED: an instance over its source's shared
 * batch, placed by its world matrix (modelTex row `caster`: the matrix's three rows). */
void main()
{
#ifdef PLACED
  vPos = vec4(pos, 1.0) * mat3x4(texelFetch(modelTex, ivec2(0, caster), 0),
                                 texelFetch(modelTex, ivec2(1, caster), 0),
                                 texelFetch(modelTex, ivec2(2, caster), 0));
#else
  vPos = pos;
#endif
  gl_Position = viewProjection * vec4(vPos, 1.0);
}
