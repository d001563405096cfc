/* Blender's Image Texture node per pixel (GLSL twin of core/textures.py sample): texel
 * centres at ((i + 0.5) / W, (j + 0.5) / H), row 0 at v = 0; interpolation 0 Closest,
 * 1 Linear, 2 Cubic (uniform B-spline); extension 0 Repeat, 1 Extend, 2 Clip, 3 Mirror.
 * texInfo = (interpolation, extension, source: -1 none / 0 image / 1 attribute, mix mode);
 * texMap0/1 = the Mapping node's 2D rows; mixColor = (constant colour, factor). */

int tex_wrap(int i, int n, int ext)
{
  if (ext == 0) {
    int m = i % n;
    return m < 0 ? m + n : m;
  }
  if (ext == 3) {
    int m = i % (2 * n);
    m = m < 0 ? m + 2 * n : m;
    return m < n ? m : 2 * n - 1 - m;
  }
  return clamp(i, 0, n - 1);
}

vec4 tex_fetch(sampler2D img, int x, int y, ivec2 size, int ext)
{
  return texelFetch(img, ivec2(tex_wrap(x, size.x, ext), tex_wrap(y, size.y, ext)), 0);
}

vec4 bspline(float t)
{
  float t2 = t * t, t3 = t2 * t;
  return vec4((1.0 - t) * (1.0 - t) * (1.0 - t), 3.0 * t3 - 6.0 * t2 + 4.0,
              -3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0, t3) / 6.0;
}

vec4 image_texture(sampler2D img, vec2 uv, vec4 info, vec3 map0, vec3 map1)
{
  vec2 st = vec2(dot(map0, vec3(uv, 1.0)), dot(map1, vec3(uv, 1.0)));
  ivec2 size = textureSize(img, 0);
  int interp = int(info.x), ext = int(info.y);
  if (ext == 2 && (st.x < 0.0 || st.x > 1.0 || st.y < 0.0 || st.y > 1.0)) {
    return vec4(0.0);
  }
  vec2 p = st * vec2(size) - 0.5;
  /* a NaN or huge coordinate must not index outside the texture: clamp first */
  p = clamp(p, vec2(-1e6), vec2(1e6));
  if (interp == 0) {
    return tex_fetch(img, int(floor(p.x + 0.5)), int(floor(p.y + 0.5)), size, ext);
  }
  ivec2 i0 = ivec2(floor(p));
  vec2 f = p - vec2(i0);
  if (interp == 2) {
    vec4 wx = bspline(f.x), wy = bspline(f.y);
    vec4 sum = vec4(0.0);
    for (int j = 0; j < 4; j++) {
      for (int i = 0; i < 4; i++) {
        sum += wx[i] * wy[j] * tex_fetch(img, i0.x - 1 + i, i0.y - 1 + j, size, ext);
      }
    }
    return sum;
  }
  vec4 a = mix(tex_fetch(img, i0.x, i0.y, size, ext), tex_fetch(img, i0.x + 1, i0.y, size, ext),
               f.x);
  vec4 b = mix(tex_fetch(img, i0.x, i0.y + 1, size, ext),
               tex_fetch(img, i0.x + 1, i0.y + 1, size, ext), f.x);
  return mix(a, b, f.y);
}

/* core.textures.ColorSource.combine: mode 0 none, 1 / 2 Mix / Multiply with the source as
 * the node's first input, 3 / 4 the same with the source second */
vec3 combine_colour(vec3 c, float mode_f, vec4 mixColor)
{
  int mode = int(mode_f + 0.5);
  if (mode == 0) {
    return c;
  }
  bool first = mode <= 2;
  vec3 a = first ? c : mixColor.rgb;
  vec3 b = first ? mixColor.rgb : c;
  float f = mixColor.a;
  return (mode == 2 || mode == 4) ? a * (1.0 - f + f * b) : mix(a, b, f);
}

/* the colour of a textured input at this pixel (texInfo.z: 0 image at uv, 1 attribute) */
vec3 input_colour(sampler2D img, vec2 uv, vec4 attr, vec4 info, vec3 map0, vec3 map1,
                  vec4 mixColor)
{
  vec3 c = info.z < 0.5 ? image_texture(img, uv, info, map0, map1).rgb : attr.rgb;
  return max(combine_colour(c, info.w, mixColor), vec3(0.0));
}
