"""What the add-on stores in the .blend, as bytes: the names and layouts of the blobs (core.common.codec), bpy-free."""
