"""The precompute and the frame as bpy-free steps: the trace run between gather and commit, and what a frame says about each object's stored data."""
