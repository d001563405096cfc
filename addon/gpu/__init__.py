"""GPU drawing: the shader builder, textures and batches, the per-pixel passes."""
