/* Adaptive anti-aliasing (addon/gpu/drawing.py render_offscreen): over the s x s samples of
 * the frame, a pixel that needs its samples (maskTex, core.shading.pixel_filter.refine_mask)
 * is left alone; every other pixel's samples take the pilot frame's pixel.  Drawn first with
 * depth writes and no colour (the near-plane depth keeps every later draw off those samples),
 * and last with depth test EQUAL (their colour). */
void main()
{
  /* the sample's pixel: centres (i + 0.5) / s floor to i / s exactly (a float division,
   * not an integer one per lane) */
  ivec2 p = ivec2(floor(gl_FragCoord.xy / float(samples)));
  if (texelFetch(maskTex, p, 0).r > 0.5) {
    discard;
  }
  fragColor = texelFetch(pilotTex, p, 0);
}
