/* Per-vertex radiance with a per-pixel colour (addon/gpu/drawing.py textured_batch): the
 * method's radiance split into what the slot's colour multiplies (vDiffuse, with
 * core.scene.mesh.closed_side in w) and the rest (vSpecular); UVs or a colour attribute. */
void main()
{
  vDiffuse = diffuse;
  vSpecular = specular;
  vUv = uv;
  vAttr = attr;
  gl_Position = viewProjection * vec4(pos, 1.0);
}
