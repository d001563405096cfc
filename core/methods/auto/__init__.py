"""AUTO: the per-object choice of method and budget, its screen weights."""
