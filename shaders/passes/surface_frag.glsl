/* Per-vertex radiance: vRadiance.a is core.scene.mesh.closed_side (a closed mesh's inner
 * side is black, common.glsl inner_side).  Radiance is clamped at zero where a basis rings
 * below it. */
void main()
{
  if (other_copy(vRadiance.a)) discard;
  vec3 rgb = inner_side(vRadiance.a) ? vec3(0.0) : max(vRadiance.rgb, vec3(0.0));
#ifdef ADDED
  fragColor = vec4(rgb, 0.0);          /* added onto the frame: its coverage is drawn */
#else
  fragColor = vec4(rgb, 1.0);
#endif
}
