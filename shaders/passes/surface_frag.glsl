/* Per-vertex radiance: vRadiance.a is core.scene.mesh.closed_side (a closed mesh's inner
 * side is black, common.glsl inner_side).  Radiance is clamped at zero where a basis rings
 * below it.  DATA: a data render pass's per-vertex value (depth, position, normal, AO),
 * written as it is on either side (addon/frame/passes.py). */
void main()
{
  if (other_copy(vRadiance.a)) discard;
#ifdef DATA
  fragColor = vec4(vRadiance.rgb, 1.0);
  return;
#endif
  vec3 rgb = inner_side(vRadiance.a) ? vec3(0.0) : max(vRadiance.rgb, vec3(0.0));
#ifdef ADDED
  fragColor = vec4(rgb, 0.0);          /* added onto the frame: its coverage is drawn */
#else
  fragColor = vec4(rgb, 1.0);
#endif
}
