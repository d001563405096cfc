/* vRadiance.a is core.scene.mesh.closed_side: 0 open, +1/-1 a closed mesh whose front faces
 * look outward/inward.  Its inner side sees only itself: no direct light, as in Cycles.
 * Radiance is clamped at zero where a basis rings below it. */
bool inner_side(float side)
{
  return side > 0.5 ? !gl_FrontFacing : (side < -0.5 ? gl_FrontFacing : false);
}

void main()
{
  vec3 rgb = inner_side(vRadiance.a) ? vec3(0.0) : max(vRadiance.rgb, vec3(0.0));
  fragColor = vec4(rgb, 1.0);
}
