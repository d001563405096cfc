void main()
{
  fragColor = vec4(vRadiance.rgb, 1.0);
}
