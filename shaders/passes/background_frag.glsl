/* The world as Cycles shows it: an equirectangular Environment Texture read at
 *   u = 0.5 - atan2(t.y, t.x) / (2 pi),  v = acos(t.z) / pi  (v = 0 is the top row),
 * with t = texRotation * d the Mapping node's rotation applied to the view ray d.
 * The texture is uploaded top row first, so v is used as the texture's t.
 * Negative light (a negative Strength) is drawn as zero; the export warns. */
void main()
{
  vec4 a = invViewProjection * vec4(vNdc, -1.0, 1.0);
  vec4 b = invViewProjection * vec4(vNdc, 1.0, 1.0);
  vec3 d = normalize(b.xyz / b.w - a.xyz / a.w);
  vec3 t = texRotation * d;
  float u = fract(0.5 - atan(t.y, t.x) / (2.0 * PI));
  float v = acos(clamp(t.z, -1.0, 1.0)) / PI;
  fragColor = vec4(max(texture(envMap, vec2(u, v)).rgb * strength, vec3(0.0)), 1.0);
}
