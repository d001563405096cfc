/* Per-vertex radiance times the slot's colour per pixel: texInfo.z 0 an image texture at
 * vUv, 1 a colour attribute (vAttr) (texture.glsl); vDiffuse.a the closed side. */
void main()
{
  if (other_copy(vDiffuse.a)) discard;
  vec3 c = input_colour(albedoTex, vUv, vAttr, texInfo, texMap0, texMap1, mixColor);
  vec3 rgb = inner_side(vDiffuse.a) ? vec3(0.0) : max(vDiffuse.rgb * c + vSpecular, vec3(0.0));
#ifdef ADDED
  fragColor = vec4(rgb, 0.0);          /* added onto the frame: its coverage is drawn */
#else
  fragColor = vec4(rgb, 1.0);
#endif
}
