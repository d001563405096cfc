"""The scene as arrays: meshes and shading points, traced visibility, rigid motion, shadow fields of moving objects, textures."""
