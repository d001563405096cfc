"""Pure-numpy core of prt_relight (never imports bpy)."""
