/* The distance from the lamp to what each face sees (lights_frag.glsl local_visibility). */
void main()
{
  fragColor = vec4(length(vPos - lamp));
}
