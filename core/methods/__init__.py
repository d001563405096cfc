"""One package per shading method's numerics (the add-on's methods/ draws them)."""
