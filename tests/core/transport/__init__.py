"""core/transport: gather clusters, transfer rows, the frame's bounce."""
