/* One axis of the pixel filter: each output texel the weighted sum of its taps along `axis`
 * (0: x, 1: y) of frameTex, sample p * samples - margin + t with weight tapTex[p][t]
 * (core.shading.pixel_filter.resolve_taps: Cycles' Blackman-Harris, rows summing to 1, 0
 * beyond the frame).  Two draws, x then y, resolve a supersampled frame on the GPU, so
 * only its pixels are read back. */
void main()
{
  ivec2 p = ivec2(gl_FragCoord.xy);
  ivec2 size = textureSize(frameTex, 0);
  int n = axis == 0 ? size.x : size.y;
  int q = axis == 0 ? p.x : p.y;
  vec4 sum = vec4(0.0);
  for (int t = 0; t < taps; t++) {
    float w = texelFetch(tapTex, ivec2(t, q), 0).r;
    int j = clamp(q * samples - margin + t, 0, n - 1);
    sum += w * texelFetch(frameTex, axis == 0 ? ivec2(j, p.y) : ivec2(p.x, j), 0);
  }
  fragColor = sum;
}
