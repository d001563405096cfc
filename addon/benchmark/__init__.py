"""prt.report: the speed/error sweep inside Blender and its hard cases."""
