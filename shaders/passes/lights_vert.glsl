/* Compact light sources per pixel (addon/gpu/lights.py): per-corner position and normal, and
 * the UVs or colour attribute of a textured colour input, the tangent and bitangent sign of
 * a normal map.  PLACED: an instance drawn over its source's shared normals (its own world
 * positions, as every pass draws them), turned by its normal matrix (paramTex row 0, texels
 * 21-23: core.scene.mesh.normal_matrix's rows; addon/gpu/lights.py _object_batches). */
void main()
{
  vPos = pos;
#ifdef PLACED
  /* unit, as the world batches' normals are (an uneven scale would weigh the interpolation) */
  vNrm = normalize(nrm * mat3(texelFetch(paramTex, ivec2(21, 0), 0).xyz,
                              texelFetch(paramTex, ivec2(22, 0), 0).xyz,
                              texelFetch(paramTex, ivec2(23, 0), 0).xyz));
#else
  vNrm = nrm;
#endif
  vUv = uv;
  vAttr = attr;
  vTng = tng;
  gl_Position = viewProjection * vec4(pos, 1.0);
}
