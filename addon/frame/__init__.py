"""What a frame needs (FrameState), the render engine, dynamic objects, caches."""
