"""bpy <-> core: scene, material, texture and lamp export; the precompute's gather and commit; storage in ID properties; scene builders."""
